"""``python -m bridge calibrate ...`` (the pipeline of :mod:`bridge.pipeline`),
``python -m bridge figure2 ...`` (the study's Figure 2 over replicas, :mod:`bridge.study_figure`)
and ``python -m bridge --version``; the console script ``clay-bridge`` is the same.

Exit codes (:mod:`clay_cli`): 0 done; 1 the calibration could not run or an
internal error; 2 bad input (one line; an ``--out`` holding an earlier calibration is refused
unless ``--overwrite``, which deletes only the files its ``calibration_files.json`` lists:
:mod:`bridge.outputs`); 4 disk full (ENOSPC/EDQUOT, one line).
"""

from __future__ import annotations

import sys

from bridge import __version__

USAGE = (
    "usage: python -m bridge [--version] {calibrate,figure2} [options]\n"
    "  calibrate   calibrate the TIV model on DEM results, predict, draw and report "
    "(python -m bridge calibrate --help)\n"
    "  figure2     the study's Figure 2 over replicas: DEM mean ± 95 % against the TIV model "
    "with Table 1 (python -m bridge figure2 --help)"
)


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``calibrate`` to :func:`bridge.pipeline.main` and ``figure2`` to
    :func:`bridge.study_figure.main`; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--version"]:
        print(f"bridge {__version__}")
        return 0
    if argv[:1] in (["-h"], ["--help"]):
        print(USAGE)
        return 0
    if argv[:1] == ["figure2"]:
        from bridge.study_figure import main as figure2

        return figure2(argv[1:], prog="python -m bridge figure2")
    if argv[:1] != ["calibrate"]:
        given = argv[0] if argv else "nothing"
        print(
            f"python -m bridge: error: unknown command {given!r}; allowed: calibrate, figure2 "
            "(python -m bridge calibrate --help)",
            file=sys.stderr,
        )
        return 2
    from bridge.pipeline import main as calibrate

    return calibrate(argv[1:], prog="python -m bridge calibrate")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
