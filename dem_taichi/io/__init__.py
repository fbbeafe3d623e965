"""Results layer of the DEM engine: netCDF schema, writers, readers, checkpoints, provenance.

Imports numpy, netCDF4 and xarray only (never Taichi), so that the bridge can read DEM results
on machines without Taichi.

Typical use by the engine::

    attrs = provenance_attrs(scene_text, "cpu", "f64", seed, " ".join(sys.argv),
                             taichi_version=ti.__version__)
    with HistoryWriter(out / "history.nc", attrs=attrs) as history:
        history.append(simulation.measure() | {"stage": "A_to_C"})   # one record per output
        save_checkpoint(checkpoint_path(out, step), simulation.get_state(), {"step": step})
        rotate_checkpoints(out, keep=2)
    # exact resume: arrays, meta = load_checkpoint(latest_checkpoint(out)), then
    # HistoryWriter(out / "history.nc", attrs=attrs, resume=True, resume_after_step=meta["step"])

and by the bridge: ``open_history(path)``, ``open_probes(path)``, ``open_configuration(path)``.
"""

from .checkpoint import (
    CheckpointError,
    checkpoint_meta,
    checkpoint_path,
    latest_checkpoint,
    load_checkpoint,
    rotate_checkpoints,
    save_checkpoint,
)
from .provenance import provenance_attrs
from .readers import open_configuration, open_history, open_probes
from .run_directory import RunDirectory, RunDirectoryError, resume_run, start_run
from .schema import (
    CONFIGURATION_VARIABLES,
    HISTORY_VARIABLES,
    PROBE_VARIABLES,
    STAGE_CODES,
    Variable,
    stage_code,
    stage_label,
)
from .writers import HistoryWriter, make_dataset, write_configuration, write_dataset

__all__ = [
    "CONFIGURATION_VARIABLES",
    "HISTORY_VARIABLES",
    "PROBE_VARIABLES",
    "STAGE_CODES",
    "CheckpointError",
    "HistoryWriter",
    "RunDirectory",
    "RunDirectoryError",
    "checkpoint_meta",
    "checkpoint_path",
    "latest_checkpoint",
    "load_checkpoint",
    "Variable",
    "make_dataset",
    "open_configuration",
    "open_history",
    "open_probes",
    "provenance_attrs",
    "resume_run",
    "rotate_checkpoints",
    "save_checkpoint",
    "stage_code",
    "stage_label",
    "start_run",
    "write_configuration",
    "write_dataset",
]
