"""Stage 7 of the pipeline, the applications: the ``amsfe`` command line (``cli``,
``arguments``) and what its commands run: ``simulate`` (a run folder with figures),
``reproduce`` (the paper's comparison), ``check`` (every generated function against
``reference``, Pinocchio's numerics), ``bench``, ``study``, ``sweep``, and ``plots`` (the
figures, drawn from finished runs).

May import every earlier room; only ``cli`` (and ``python -m amsfe_sym``) may import the
other applications' command-line glue.
"""
