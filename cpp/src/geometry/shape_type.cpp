#include "wmo/geometry/shapes.h"

namespace wmo {

const char* to_string(ShapeType t) {
  switch (t) {
    case ShapeType::kSphere: return "sphere";
    case ShapeType::kBox: return "box";
    case ShapeType::kCapsule: return "capsule";
    case ShapeType::kCylinder: return "cylinder";
    case ShapeType::kConvexHull: return "convex_hull";
    case ShapeType::kTriangleMesh: return "triangle_mesh";
    case ShapeType::kPlane: return "plane";
    case ShapeType::kCompound: return "compound";
    case ShapeType::kCount: break;
  }
  return "unknown";
}

}  // namespace wmo
