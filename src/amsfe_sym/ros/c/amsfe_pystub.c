/* amsfe_pystub.c: the two data symbols of the Python type support that librcl's wheel
 * loads (librcl links every message package's rosidl_generator_py library, whose
 * functions are never called by a C node and are bound lazily; these two are data,
 * resolved when the library loads: PyExc_RuntimeError, _Py_TrueStruct).  Linked into
 * amsfe_node instead of libpython, so no interpreter is loaded
 * (readelf -rW lib*__rosidl_generator_py.so | grep GLOB_DAT lists them). */
__attribute__((visibility("default"))) char PyExc_RuntimeError[16];
__attribute__((visibility("default"))) char _Py_TrueStruct[64];
