"""Foundation: what every stage may use and that depends on nothing of the pipeline.

Modules: ``toml`` (reading and writing TOML; the typed value readers of robot.toml and
scenario files), ``camera_frame`` (the :class:`CameraFrame` value a camera delivers),
``provenance`` (commit, machine and versions recorded with every result), ``interrupts``
(Ctrl-C and SIGTERM held while third-party code runs, raised at the toolkit's checkpoints).

May import: errors (and the package's ``__version__``); numpy and the standard library only.
"""
