"""Experiments: what accuracy costs in time (book chapter "What accuracy costs").

* :mod:`.metrics`     relMSE exactly as the papers define it, MSE, trimmed relMSE, slopes, the bias /
  variance split over seeds;
* :mod:`.progressive` the runner: time or pass budgets, geometric snapshots, per-stage timing;
* :mod:`.solvers`     frames -> final images through :mod:`gdlearn.reconstruct` by solver name;
* :mod:`.study`       equal-time studies: methods x scenes x seeds -> tidy records;
* :mod:`.references`  cached long-run references, Mitsuba 3 references, their noise floor;
* :mod:`.executors`   serial, local process pool, Dask distributed;
* :mod:`.plots`       convergence plots, image grids, error maps, stage bars, ratios;
* toy estimators of an analytic image (exact answer known) live in :mod:`gdlearn.teaching.toy`.
"""
from gdlearn.experiments.metrics import (bias_variance, loglog_slope, mse, relmse, relmse_floor, relmse_map,
                                         relmse_trimmed, time_to_reach)
from gdlearn.experiments.progressive import Run, Snapshot, pass_schedule, run, time_schedule
from gdlearn.experiments.study import Method, SceneFile, Study, Task, equal_time, run_task

__all__ = ["bias_variance", "relmse", "relmse_map", "relmse_trimmed", "relmse_floor", "mse", "loglog_slope",
           "time_to_reach", "run", "Run", "Snapshot", "pass_schedule", "time_schedule", "Method",
           "SceneFile", "Study", "Task", "equal_time", "run_task"]
