"""Stage 3 of the pipeline, codegen: symbolic functions -> C source + header + shared library +
manifest, one library per robot in ``generated/<name>/``, cached by content.

Modules: ``build`` (:func:`generate`: symbols -> C -> ``.so`` -> manifest, atomically),
``cache`` (paths, compiler flags, the content hash, locks, stale temporary folders),
``manifest`` (the manifest document), ``libraries`` (:func:`load_library`,
:func:`library_for`, :func:`library_at_period`: a robot's, a scenario's or a robot's at another
sampling interval, loaded), ``modes`` (each joint's elastic mode, the spec at another T),
``preflight`` (checks of a scenario against its robot that need no library).

May import: errors, core, load, scenario, symbolic (only when building), runtime (to load what
it built) and the estimator registry (to check a scenario's camera timing).
"""

from amsfe_sym.codegen.build import GenerateResult, cached_library, generate
from amsfe_sym.codegen.cache import (
    ALL_PARTS,
    DEFAULT_CFLAGS,
    cflags,
    clean_stale_tmp,
    compiler,
    content_hash,
    default_out_dir,
)
from amsfe_sym.codegen.libraries import library_at_period, library_for, load_library

__all__ = [
    "ALL_PARTS",
    "DEFAULT_CFLAGS",
    "GenerateResult",
    "cached_library",
    "cflags",
    "clean_stale_tmp",
    "compiler",
    "content_hash",
    "default_out_dir",
    "generate",
    "library_at_period",
    "library_for",
    "load_library",
]
