"""Bridge from DEM results (netCDF histories) to the TIV model: series, calibration, predictions.

Reads DEM *results* only (plain xarray), never the engine, so it runs without Taichi.
"""

__version__ = "0.1.0"
