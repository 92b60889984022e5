"""Stage 2 of the pipeline, symbolic: CasADi SX functions built by walking Pinocchio's model
tree (the PyPI ``pin`` wheel has no ``pinocchio.casadi``): dynamics, the camera map, the
discrete flexible-joint transition, its inverse and jacobians, the control laws' terms and
the estimators' C functions (``model.build_functions`` registers them all).

May import: errors, core, load.  Nothing here is imported at run time: the runtime loads
what :mod:`amsfe_sym.codegen` compiled.
"""
