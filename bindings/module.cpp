// pybind11 module wmo._core. Thin: conversions and GIL handling only; every algorithm
// lives in cpp/. Submodule bindings are registered from the other files in bindings/.
#include <pybind11/pybind11.h>

#include "wmo/math.h"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "WMO C++ core";
  // C++ errors become Python exceptions in one place.
  py::register_exception<wmo::InvalidArgument>(m, "InvalidArgument", PyExc_ValueError);
}
