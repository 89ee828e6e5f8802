// pybind11 module wmo._core. Thin: conversions and GIL handling only; every algorithm
// lives in cpp/. Submodule bindings are registered from the other files in bindings/
// (math.cpp: Pose; shapes.cpp: shapes; queries.cpp: result types and wmo._core.geometry;
// world.cpp: World and Body; codec.cpp: wmo._core.codec).
#include <pybind11/pybind11.h>

#include "common.h"
#include "wmo/math.h"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "WMO C++ core";
  // C++ errors become Python exceptions in one place: wmo::InvalidArgument (bad user
  // input, message names the field and the value) -> wmo.InvalidArgument, a subclass of
  // ValueError. Wrong argument types and array shapes raise TypeError (common.h).
  py::register_exception<wmo::InvalidArgument>(m, "InvalidArgument", PyExc_ValueError);

  wmo::bindings::bind_math(m);
  wmo::bindings::bind_shapes(m);
  py::module_ geometry = m.def_submodule(
      "geometry", "Pair queries, ray casts and their batched forms (wrapped by wmo.geometry).");
  wmo::bindings::bind_queries(m, geometry);
  wmo::bindings::bind_world(m);
  wmo::bindings::bind_codec(m);
}
