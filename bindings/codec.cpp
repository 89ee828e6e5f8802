// wmo._core.codec: the residual table coder (wmo/codec/residual_coder.h) for the remote
// snapshot stream (python/wmo/remote/snapshot.py). Thin: array checks and GIL release.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>

#include "common.h"
#include "wmo/codec/residual_coder.h"

namespace wmo::bindings {
namespace {

using IntTable = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

IntTable to_table(py::handle obj, const std::string& field) {
  py::array a = py::array::ensure(obj);
  if (!a || a.ndim() != 2 || (a.size() && a.dtype().kind() != 'i' && a.dtype().kind() != 'u'))
    throw py::type_error(field + " must be an (N, C) integer array");
  return IntTable::ensure(a);
}

// A side table (`field`: "motion" or "previous"): None (all zeros) or the residuals'
// shape. `holder` keeps the converted array alive.
const std::int64_t* side_table(const py::object& obj, const std::string& field, IntTable& holder,
                               py::ssize_t rows, py::ssize_t columns) {
  if (obj.is_none()) return nullptr;
  holder = to_table(obj, field);
  if (holder.shape(0) != rows || holder.shape(1) != columns)
    throw_shape_error(field, "(" + std::to_string(rows) + ", " + std::to_string(columns) + ")", holder);
  return holder.data();
}

codec::ResidualLayout layout_of(py::ssize_t rows, py::ssize_t columns, std::uint32_t group_starts) {
  return {static_cast<std::int64_t>(rows), static_cast<int>(columns), group_starts};
}

}  // namespace

void bind_codec(py::module_& m) {
  py::module_ codec = m.def_submodule(
      "codec", "Entropy coding of integer residual tables (the remote snapshot stream).");
  codec.attr("MAX_RESIDUAL") = codec::kMaxResidual;
  codec.def(
      "encode_residuals",
      [](py::handle residuals, py::object motion, py::object previous, std::uint32_t group_starts) {
        IntTable values = to_table(residuals, "residuals");
        IntTable motion_holder, previous_holder;
        const std::int64_t* motion_data = side_table(motion, "motion", motion_holder, values.shape(0), values.shape(1));
        const std::int64_t* previous_data =
            side_table(previous, "previous", previous_holder, values.shape(0), values.shape(1));
        if (values.shape(1) < 1 || values.shape(1) > codec::kMaxColumns)
          throw InvalidArgument("residuals: columns must be in 1.." + std::to_string(codec::kMaxColumns) +
                                ", got " + std::to_string(values.shape(1)));
        const auto layout = layout_of(values.shape(0), values.shape(1), group_starts);
        std::vector<std::uint8_t> bytes;
        {
          py::gil_scoped_release release;
          bytes = codec::encode_residuals(values.data(), motion_data, previous_data, layout);
        }
        return py::bytes(reinterpret_cast<const char*>(bytes.data()), bytes.size());
      },
      py::arg("residuals"), py::arg("motion") = py::none(), py::arg("previous") = py::none(),
      py::arg("group_starts") = 1u,
      "Codes an (N, C) int64 table (|v| < 2**62) given side information `motion` and\n"
      "`previous` (each the same shape, or None for zeros) that the decoder has too\n"
      "(wmo/codec/residual_coder.h says how each is used). Bit c of `group_starts`\n"
      "set: column c begins a group (the previous column is no context for it). Returns\n"
      "bytes. Raises ValueError naming a value out of range.");
  codec.def(
      "decode_residuals",
      [](py::bytes data, py::ssize_t rows, py::ssize_t columns, py::object motion, py::object previous,
         std::uint32_t group_starts) {
        if (rows < 0) throw InvalidArgument("rows must be >= 0, got " + std::to_string(rows));
        if (columns < 1 || columns > codec::kMaxColumns)
          throw InvalidArgument("columns must be in 1.." + std::to_string(codec::kMaxColumns) + ", got " +
                                std::to_string(columns));
        IntTable motion_holder, previous_holder;
        const std::int64_t* motion_data = side_table(motion, "motion", motion_holder, rows, columns);
        const std::int64_t* previous_data = side_table(previous, "previous", previous_holder, rows, columns);
        std::string_view view = data;
        IntTable out({rows, columns});
        const auto layout = layout_of(rows, columns, group_starts);
        std::string why;
        bool ok;
        {
          py::gil_scoped_release release;
          ok = codec::decode_residuals(reinterpret_cast<const std::uint8_t*>(view.data()), view.size(), motion_data,
                                       previous_data, layout, out.mutable_data(), &why);
        }
        if (!ok) throw InvalidArgument("residual stream: " + why);
        return out;
      },
      py::arg("data"), py::arg("rows"), py::arg("columns"), py::arg("motion") = py::none(),
      py::arg("previous") = py::none(), py::arg("group_starts") = 1u,
      "Decodes a table coded by encode_residuals with the same motion, previous and\n"
      "group_starts:\n"
      "an (rows, columns) int64 array. Raises ValueError for a malformed stream (a class\n"
      "beyond 62 bits, truncated, or bytes after the table); work is bounded by the\n"
      "table's size whatever the bytes.");
}

}  // namespace wmo::bindings
