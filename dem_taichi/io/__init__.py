"""Results layer of the DEM engine: netCDF schema, writers, readers, checkpoints, provenance.

Imports numpy, netCDF4 and xarray only (never Taichi), so that the bridge can read DEM results
on machines without Taichi.
"""

from .checkpoint import (
    CheckpointError,
    checkpoint_path,
    latest_checkpoint,
    load_checkpoint,
    rotate_checkpoints,
    save_checkpoint,
)
from .provenance import provenance_attrs
from .readers import open_configuration, open_history, open_probes
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
    "checkpoint_path",
    "latest_checkpoint",
    "load_checkpoint",
    "Variable",
    "make_dataset",
    "open_configuration",
    "open_history",
    "open_probes",
    "provenance_attrs",
    "rotate_checkpoints",
    "save_checkpoint",
    "stage_code",
    "stage_label",
    "write_configuration",
    "write_dataset",
]
