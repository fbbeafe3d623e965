"""Bridge from DEM results (netCDF histories) to the TIV model: series, calibration, predictions.

Reads DEM *results* only (``dem_taichi.io``: numpy/netCDF/xarray), never the engine, so it runs
without Taichi. Modules, in the order of the pipeline:

- :mod:`bridge.series` — DEM history/probes → model series per path (isotropic A→B, K0 A→C,
  unloading C→B) with a stated, switchable 2D → 3D convention (``"triaxial"`` default,
  ``"plane"``), an explicit stress scale (kPa per DEM unit) and fabric sign/scale
  (β_model = −F (β_yy − β_xx)); the inverse writes DEM-schema datasets of model runs;
- :mod:`bridge.convention` — that convention (:class:`~bridge.convention.Convention`, both
  ways) and :class:`~bridge.convention.SeriesError`, re-exported by :mod:`bridge.series`;
- :mod:`bridge.units` — the units of every variable read from a results file, parsed with
  pint: DEM units (``"1"`` + ``dem_units``) or a pressure unit for stresses and moduli,
  dimensionless for v and fabric; anything else (or no ``units``) refused naming it;
- :mod:`bridge.moduli` — the model's elastic moduli at measured states (batched inversion);
- :mod:`bridge.runs` — model runs along the DEM paths, sampled at the DEM points;
- :mod:`bridge.calibration` — a subpackage: staged least squares (``fit``: compressibility
  λ*, N; elastic k, g, n, r, ω; fabric c, s, z, M), its ``options`` and ``result`` (standard
  errors, fit quality), and what the data determine (``identifiability``: profile likelihoods);
- :mod:`bridge.predict` — predictions labelled fitted / out of sample (E_h/E_v along K0);
- :mod:`bridge.figures`, :mod:`bridge.report` — DEM points vs TIV lines; markdown report;
- :mod:`bridge.pipeline` — ``calibrate_from_results`` (returns a
  :class:`bridge.pipeline_result.PipelineResult`) and ``python -m bridge.pipeline``;
- :mod:`bridge.pipeline_options` — what the pipeline is asked to do (``PipelineOptions``)
  and the stress scale a run's options and files give, re-exported by :mod:`bridge.pipeline`;
- :mod:`bridge.command_options` — the command-line options ``calibrate`` and ``figure2`` share;
- :mod:`bridge.replicas` — calibration on replica runs (their record-by-record mean, and the
  spread of the parameters over the replicas);
- :mod:`bridge.replica_bands` — the replicas' mean and 95 % interval of the mean, record by
  record (Student t);
- :mod:`bridge.study_figure`, :mod:`bridge.study_figure_panels` — the study's Figure 2 over
  replicas: our mean ± 95 % against the TIV model with Table 1 along our mean paths, and its
  table (``python -m bridge figure2``);
- :mod:`bridge.synthetic` — DEM-like results made by the model itself (exact-recovery checks).

Example::

    from bridge.pipeline import PipelineOptions, calibrate_from_results
    outcome = calibrate_from_results("run/history.nc", "run/probes.nc", "run/bridge",
                                     PipelineOptions(stress_scale_kpa=1.0))
    outcome.parameters, outcome.report     # a PipelineResult; outcome.to_dict(): JSON
"""

__version__ = "0.1.0"
