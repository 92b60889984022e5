"""Stage 6 of the pipeline, sim: the closed loop on a simulated arm.

- ``builders``: a scenario + a library -> plant start, sensors, estimator, controller;
- ``loop``: :func:`~amsfe_sym.sim.loop.run`, the closed-loop simulation (the Python
  reference loop, or the compiled one of ``compiled``);
- ``compiled``: the same run on the library's C loop;
- ``result``: :class:`~amsfe_sym.sim.result.RunResult` and the counters both runtimes fill;
- ``record``: the run folder and the summary metrics (no figures: the apps draw them).

The sensors and trajectories are :mod:`amsfe_sym.signals`.  May import: errors, core,
scenario, signals, runtime, estimation, control.  Importing this package does not import
the closed loop; import those modules by name.
"""
