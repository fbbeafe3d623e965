"""Render a ParaView snapshot (``paraview/state_<label>.vtu``) headless to a PNG with pyvista.

    python benchmarks/render_snapshot.py RUN/paraview/state_C.vtu OUT.png [--color charge]

The discs are drawn as circles of their diameter, coloured by a point array (``charge``,
``rod_id``, ``angle``, ``body_torque`` …), the periodic cell as a box. pyvista (and VTK) are not
dependencies of the project: ``pip install pyvista`` in any environment; off-screen rendering
needs no display.
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("snapshot", help="a .vtu written by dem_taichi.io.vtk_snapshots")
    parser.add_argument("png", help="the image to write")
    parser.add_argument("--color", default="charge", help="point array to colour by")
    parser.add_argument("--size", type=int, default=900, help="image width and height (px)")
    args = parser.parse_args(argv)
    try:
        import pyvista as pv
    except ImportError:
        print("render_snapshot: needs pyvista (pip install pyvista)", file=sys.stderr)
        return 2
    pv.OFF_SCREEN = True
    grid = pv.read(args.snapshot)
    if args.color not in grid.point_data:
        print(
            f"render_snapshot: no point array {args.color!r}; "
            f"allowed: {', '.join(grid.point_data.keys())}",
            file=sys.stderr,
        )
        return 2
    discs = grid.glyph(geom=pv.Disc(inner=0.0, outer=0.5, c_res=24), scale="diameter", orient=False)
    lx, ly = (float(v) for v in grid.field_data["cell_lengths"].ravel())
    plotter = pv.Plotter(off_screen=True, window_size=(args.size, args.size))
    plotter.add_mesh(discs, scalars=args.color, cmap="coolwarm", show_scalar_bar=True)
    plotter.add_mesh(pv.Box((0, lx, 0, ly, 0, 0)).outline(), color="black", line_width=2)
    plotter.view_xy()
    plotter.set_background("white")
    plotter.screenshot(args.png)
    print(args.png)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
