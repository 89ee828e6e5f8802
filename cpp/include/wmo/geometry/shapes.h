// WMO geometry layer: shapes, support maps and mass properties.
//
// Every shape lives in its own local frame. Axis conventions: capsules and cylinders
// are aligned with the local Y axis (Jolt's and Bullet's default); a plane is the
// half-space { x : dot(normal, x) <= offset }.
//
// Convex shapes are "core + radius" (Jolt's convex radius, parry's rounded shapes):
// a sphere is a point core with radius r, a capsule a segment core with radius r, a
// rounded box a smaller box core with radius r. GJK runs on the core and adds the
// radius, so curved shapes are exact rather than sampled.
//
// Shapes are immutable after construction and shared through std::shared_ptr<const Shape>,
// so one shape can be used by many bodies and by Python at once.
#pragma once

#include <array>
#include <cmath>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "wmo/math.h"
#include "wmo/types.h"

namespace wmo {

namespace detail {

/// Squared length below which a support direction counts as zero. Directions come from
/// GJK and from contact normals, both of order 1 or larger in length; a length of
/// 1e-150 is far below anything meaningful yet its square stays a normal double (no
/// underflow). The shapes' support maps (shapes.cpp) and GJK's inlined supports
/// (gjk.h) share it, so the two agree bit for bit.
constexpr Real kTinyDirSq = 1e-300;

/// dir / |dir|, or +X for a zero or non-finite direction: any point of a shape may
/// answer a zero direction; the one along +X keeps results deterministic and finite.
inline Vec3 unit_or_x(const Vec3& dir) {
  const Real n2 = dir.squaredNorm();
  if (!(n2 > kTinyDirSq) || !std::isfinite(n2)) return Vec3::UnitX();
  return dir / std::sqrt(n2);
}

/// Sign with sign(0) = +1, so a support map picks a definite vertex for a zero
/// component. Arithmetic on the comparison rather than a choice, so that it compiles
/// without a branch wherever it is inlined: a support direction's signs are random
/// (GJK, EPA), and where GCC made the choice a branch it was mispredicted half the
/// time (sphere-box GJK 1.3-1.5x slower in one build).
inline Real sign_or_plus(Real x) { return Real(1) - Real(2) * static_cast<Real>(x < 0); }

}  // namespace detail

enum class ShapeType : std::uint8_t {
  kSphere = 0,
  kBox,
  kCapsule,
  kCylinder,
  kConvexHull,
  kTriangleMesh,
  kPlane,
  kCompound,
  kCount
};

const char* to_string(ShapeType t);

/// Mass properties of a solid shape of uniform density.
struct MassProperties {
  Real volume = 0;                          ///< unit: m^3
  Real mass = 0;                            ///< unit: kg (density * volume)
  Vec3 center_of_mass = Vec3::Zero();       ///< unit: m, in the shape's local frame
  Mat3 inertia = Mat3::Zero();              ///< unit: kg m^2, about the centre of mass, local axes
};

/// Largest coordinate used for the bounding box of an unbounded shape (plane), in
/// metres. Finite so that broadphase arithmetic (surface areas, sorting) stays finite.
constexpr Real kUnboundedExtent = 1e9;

class Shape {
 public:
  explicit Shape(ShapeType type) : type_(type) {}
  virtual ~Shape() = default;
  Shape(const Shape&) = delete;
  Shape& operator=(const Shape&) = delete;

  ShapeType type() const { return type_; }
  /// True for sphere, box, capsule, cylinder and convex hull.
  bool is_convex() const { return type_ <= ShapeType::kConvexHull; }

  /// Bounding box in the shape's local frame (unit: m).
  virtual Aabb local_aabb() const = 0;
  /// World bounding box for the shape placed at `pose`. The default transforms the
  /// local box (Arvo); curved shapes override it with a tight box.
  virtual Aabb world_aabb(const Pose& pose) const { return local_aabb().transformed(pose); }

  /// True if the shape encloses a volume (all convex shapes and compounds). Planes and
  /// triangle meshes are not solid.
  virtual bool is_solid() const { return is_convex(); }
  /// Mass properties for a uniform density (kg/m^3). Throws InvalidArgument for
  /// non-solid shapes or a non-positive density.
  virtual MassProperties mass_properties(Real density) const;

 private:
  ShapeType type_;
};

/// Up to kMaxFaceVertices points describing the feature of a convex shape that faces a
/// direction: a polygon (face), 2 points (edge) or 1 point (vertex), in the local frame,
/// on the outer surface (radius included). Used to build contact manifolds by clipping.
constexpr int kMaxFaceVertices = 32;
struct SupportingFace {
  int count = 0;
  /// vertices[0..count); the rest is left uninitialised (zeroing the 32 of them cost
  /// every generic or mesh contact 768 bytes of stores a face).
  std::array<Vec3, kMaxFaceVertices> vertices;
  /// Identifies the feature (face index, or a vertex/edge code) for persistent ids.
  std::uint32_t feature = 0;
  /// For a polygon (count >= 3): the outward unit normal of its plane (local frame),
  /// the shape's own (a box's axis, a hull's face plane, a cylinder's axis), so contact
  /// clipping need not recompute it from the vertices. Unset for a segment or a point.
  Vec3 normal;
};

/// A convex shape: core + radius. `support` includes the radius, `support_core` does
/// not. `dir` need not be normalised but must be non-zero; for a zero direction any
/// point of the shape is returned.
class ConvexShape : public Shape {
 public:
  using Shape::Shape;
  /// Point of the shape furthest along `dir` (local frame).
  virtual Vec3 support(const Vec3& dir) const = 0;
  /// Point of the core furthest along `dir` (local frame).
  virtual Vec3 support_core(const Vec3& dir) const = 0;
  /// The convex radius: the shape is the core inflated by this radius (unit: m).
  Real radius() const { return radius_; }
  /// The face / edge / vertex whose outward normal is closest to `dir` (local frame).
  virtual void supporting_face(const Vec3& dir, SupportingFace& face) const = 0;

 protected:
  Real radius_ = 0;
};

/// Sphere of radius `radius` centred at the origin. Core: the origin.
class Sphere final : public ConvexShape {
 public:
  explicit Sphere(Real radius);
  Vec3 support(const Vec3& dir) const override;
  Vec3 support_core(const Vec3&) const override { return Vec3::Zero(); }
  void supporting_face(const Vec3& dir, SupportingFace& face) const override;
  Aabb local_aabb() const override;
  Aabb world_aabb(const Pose& pose) const override;
  MassProperties mass_properties(Real density) const override;
};

/// Box with half extents (hx, hy, hz), optionally rounded: the outer surface stays at
/// the half extents and the edges are rounded with `rounding` (unit: m), so the core is
/// a box of half extents - rounding. rounding must be < the smallest half extent.
class Box final : public ConvexShape {
 public:
  explicit Box(const Vec3& half_extents, Real rounding = 0);
  const Vec3& half_extents() const { return half_extents_; }
  /// Half extents of the core box (half_extents - rounding).
  const Vec3& core_half_extents() const { return core_; }
  Vec3 support(const Vec3& dir) const override;
  Vec3 support_core(const Vec3& dir) const override;
  void supporting_face(const Vec3& dir, SupportingFace& face) const override;
  Aabb local_aabb() const override;
  MassProperties mass_properties(Real density) const override;

 private:
  Vec3 half_extents_;
  Vec3 core_;
};

/// Capsule along local Y: segment from (0, -half_height, 0) to (0, half_height, 0)
/// inflated by `radius`. Total length 2 * (half_height + radius).
class Capsule final : public ConvexShape {
 public:
  Capsule(Real radius, Real half_height);
  Real half_height() const { return half_height_; }
  Vec3 support(const Vec3& dir) const override;
  Vec3 support_core(const Vec3& dir) const override;
  void supporting_face(const Vec3& dir, SupportingFace& face) const override;
  Aabb local_aabb() const override;
  Aabb world_aabb(const Pose& pose) const override;
  MassProperties mass_properties(Real density) const override;

 private:
  Real half_height_;
};

/// Solid cylinder along local Y, radius `cylinder_radius`, from y = -half_height to
/// +half_height. Sharp edges: its convex radius is 0.
class Cylinder final : public ConvexShape {
 public:
  Cylinder(Real cylinder_radius, Real half_height);
  Real cylinder_radius() const { return cylinder_radius_; }
  Real half_height() const { return half_height_; }
  Vec3 support(const Vec3& dir) const override;
  Vec3 support_core(const Vec3& dir) const override { return support(dir); }
  void supporting_face(const Vec3& dir, SupportingFace& face) const override;
  Aabb local_aabb() const override;
  MassProperties mass_properties(Real density) const override;

 private:
  Real cylinder_radius_;
  Real half_height_;
};

/// Convex hull of a point cloud, built with Quickhull (Barber et al. 1996). Stores the
/// polytope as a half-edge mesh: vertices, faces (planes with outward unit normals and
/// a CCW vertex loop), half-edges with twins, and the unique edges, so SAT and face
/// clipping can walk it. Coplanar triangles are merged into polygonal faces.
class ConvexHull final : public ConvexShape {
 public:
  struct Face {
    Vec3 normal;          ///< outward unit normal
    Real offset;          ///< plane: dot(normal, x) = offset
    int first_edge;       ///< one half-edge of the face's loop
    int vertex_count;     ///< number of vertices / half-edges in the loop
  };
  struct HalfEdge {
    int origin;  ///< vertex index the half-edge starts at
    int twin;    ///< opposite half-edge (in the neighbouring face)
    int next;    ///< next half-edge CCW around `face`
    int face;    ///< face to the left
  };

  /// Throws InvalidArgument naming `points` if there are fewer than 4 points, any is
  /// non-finite, or they are (within a tolerance relative to their extent) coplanar,
  /// colinear or coincident. Duplicate and interior points are dropped.
  explicit ConvexHull(const std::vector<Vec3>& points);

  // The arrays below are views into the hull's own storage (one block, see the private
  // members): valid as long as the hull lives.

  /// The hull's vertices (m, hull frame): the input points that are corners of it.
  std::span<const Vec3> vertices() const { return vertices_; }
  /// Its faces (planes in the hull frame, coplanar triangles merged).
  std::span<const Face> faces() const { return faces_; }
  /// Distance tolerance the hull was built with (unit: m): input points within it of
  /// the hull were treated as on it and dropped, face vertices lie within 2x it of their
  /// face plane. 6 * DBL_EPSILON * (max|x| + max|y| + max|z|) of the input, raised by
  /// 1e3 or 1e6 only for clouds that are degenerate within round-off.
  Real tolerance() const { return tolerance_; }
  /// The faces' loops: half-edge f.first_edge and its `next`s go CCW round face f.
  std::span<const HalfEdge> half_edges() const { return half_edges_; }
  /// One half-edge index per undirected edge (the one with the smaller index of each twin pair).
  std::span<const int> edges() const { return edges_; }
  /// Vertex indices of face `f`, CCW seen from outside.
  std::vector<int> face_vertices(int f) const;

  /// Edge k (edges()[k] = half-edge h) as the separating axis test uses it: the
  /// faces on its two sides (its arc on the Gauss map runs between their normals) and
  /// its two vertices. Precomputed at construction, so a query reads one 16-byte
  /// record per edge instead of following half-edge links.
  struct EdgeArc {
    int face1;  ///< h's face
    int face2;  ///< the twin's face
    int tail;   ///< h's origin
    int head;   ///< h's destination
  };
  std::span<const EdgeArc> edge_arcs() const { return edge_arcs_; }
  /// An edge around a vertex: its index in edges() and the vertex at its other end.
  struct VertexEdge {
    int edge;
    int other;
  };
  /// The edges around vertex v, in the order of a walk around it (h0, twin(h0).next,
  /// ... with h0 the highest-numbered half-edge leaving v): entries
  /// vertex_edges()[vertex_edge_begin()[v] .. vertex_edge_begin()[v + 1]).
  std::span<const VertexEdge> vertex_edges() const { return vertex_edges_; }
  std::span<const int> vertex_edge_begin() const { return vertex_edge_begin_; }
  /// Mean of the vertices (m, hull frame): a point inside the hull.
  const Vec3& vertex_centroid() const { return vertex_centroid_; }
  /// Distance from vertex_centroid() to the farthest vertex (m): the ball of this radius
  /// around the centroid contains the hull.
  Real outer_radius() const { return outer_radius_; }
  /// The vertices' coordinates as three arrays (x, y, z), for vectorised support
  /// searches: vertex_coords()[axis * vertices().size() + i].
  std::span<const Real> vertex_coords() const { return vertex_coords_; }

  Vec3 support(const Vec3& dir) const override { return support_core(dir); }
  Vec3 support_core(const Vec3& dir) const override;
  /// Index of the support vertex.
  int support_index(const Vec3& dir) const;
  void supporting_face(const Vec3& dir, SupportingFace& face) const override;
  Aabb local_aabb() const override { return aabb_; }
  MassProperties mass_properties(Real density) const override;

 private:
  // Every array below lies in one block of memory (storage_), each starting on a
  // 64-byte cache line, in the order the separating axis test reads them: a pair of
  // hulls out of cache then costs its misses over a few pages instead of a dozen
  // heap allocations scattered over as many (the narrowphase benchmark's hull pairs).
  struct AlignedDelete {
    void operator()(std::byte* p) const;
  };
  std::unique_ptr<std::byte[], AlignedDelete> storage_;
  std::span<const Real> vertex_coords_;
  std::span<const Face> faces_;
  std::span<const Vec3> vertices_;
  std::span<const EdgeArc> edge_arcs_;
  std::span<const VertexEdge> vertex_edges_;
  std::span<const int> vertex_edge_begin_;
  std::span<const HalfEdge> half_edges_;
  std::span<const int> edges_;
  Vec3 vertex_centroid_ = Vec3::Zero();
  Real outer_radius_ = 0;
  Aabb aabb_;
  Real tolerance_ = 0;
};

/// Half-space { x : dot(normal, x) <= offset } (local frame). Not solid, static only.
class Plane final : public Shape {
 public:
  /// `normal` is normalised; `offset` (metres) is kept as given, so it is the distance
  /// along the unit normal. Throws InvalidArgument if the normal is zero or not finite,
  /// or the offset is not finite.
  Plane(const Vec3& normal, Real offset);
  const Vec3& normal() const { return normal_; }
  Real offset() const { return offset_; }
  Aabb local_aabb() const override;
  bool is_solid() const override { return false; }

 private:
  Vec3 normal_;
  Real offset_;
};

class TriangleMeshBvh;  // defined in wmo/geometry/mesh_bvh.h

/// Concave triangle mesh (static geometry). Triangles are CCW seen from outside (the
/// face normal is (v1-v0)x(v2-v0)). Holds a BVH over its triangles and, for every
/// triangle edge, whether it is an internal (flat or concave) edge so contacts against
/// it can be suppressed or corrected (internal-edge handling).
class TriangleMesh final : public Shape {
 public:
  /// Throws InvalidArgument for non-finite vertices ("vertices[i] must be finite, got
  /// (x, y, z)"), out-of-range indices ("triangles[t] ..." with the index), or an empty
  /// mesh. Degenerate triangles are rejected with their index: a triangle whose
  /// |(v1-v0)x(v2-v0)| is at most 1e-12 * (its longest edge)^2, i.e. whose height is
  /// below 1e-12 of its longest edge (repeated indices included), has no usable normal.
  ///
  /// Adjacency is by vertex index (weld duplicate vertices first). An edge shared by
  /// exactly two triangles that traverse it in opposite directions (consistent winding)
  /// links them as neighbours; an edge used once, by three or more triangles
  /// (non-manifold) or by two triangles with inconsistent winding is a boundary edge.
  ///
  /// Edge classification: with n the triangle's normal, v the edge's first vertex and
  /// p the neighbour's vertex opposite the edge, h = n.(p - v). The edge is convex
  /// (seen from the front) if h < -tol, concave (convex seen from the back) if h > tol,
  /// and flat otherwise, with tol = kFlatEdgeRelTolerance * (diagonal of the mesh's
  /// bounding box). Boundary edges count as convex from both sides: they are real
  /// features.
  ///
  /// `one_sided`: false (the default) makes every triangle a two-sided sheet of zero
  /// thickness: a body is pushed out on whichever side less of it has passed through.
  /// true makes the mesh the surface of a solid that lies behind it (against the
  /// normals: terrain, or a closed mesh wound outwards), in the manner of Jolt's
  /// EBackFaceMode::IgnoreBackFaces, but keeping the overlaps:
  ///   * a body in front of a triangle (or touching it from the front) collides as on a
  ///     two-sided mesh, front side only;
  ///   * a body that overlaps a triangle is always pushed out through its FRONT, along
  ///     the face normal, however much of it has passed through (depth: how far its
  ///     lowest point lies behind the triangle's plane within the triangle's prism);
  ///   * a body wholly behind a triangle's plane that does not overlap it is ignored
  ///     (a speculative contact from behind would push it through the sheet).
  /// A zero-thickness ground that is two-sided lets a body whose centre is driven
  /// past its plane (a fast, thin or spinning body, or a pile's pressure) be pushed
  /// out below and fall; a one-sided ground pushes it back up. Queries (ray casts,
  /// distances) see the triangles two-sided either way.
  TriangleMesh(std::vector<Vec3> vertices, std::vector<std::array<int, 3>> triangles, bool one_sided = false);
  ~TriangleMesh() override;

  /// True if the mesh is one-sided (the constructor's `one_sided`).
  bool one_sided() const { return one_sided_; }

  const std::vector<Vec3>& vertices() const { return vertices_; }
  const std::vector<std::array<int, 3>>& triangles() const { return triangles_; }
  /// Unit normal of triangle t.
  const Vec3& triangle_normal(int t) const { return normals_[t]; }
  /// Neighbouring triangle across edge e (edge e goes from vertex e to vertex (e+1)%3)
  /// of triangle t, or -1 on a boundary.
  int neighbor(int t, int e) const { return neighbors_[t][e]; }
  /// True if edge e of triangle t is convex (a real feature that may produce contacts);
  /// false if it is flat or concave, i.e. internal to the surface.
  bool edge_is_convex(int t, int e) const { return (convex_edge_bits_[t] >> e) & 1u; }
  /// The same seen from the back of the triangle (against the normal): true for a
  /// concave edge or a boundary edge, false for a flat or convex one.
  bool edge_is_convex_from_back(int t, int e) const {
    return (convex_edge_bits_[t] >> (e + 3)) & 1u;
  }
  /// Tolerance of the flat-edge test (see the constructor), relative to the diagonal of
  /// the mesh's bounding box: 1e-9 lies ~4.5e6 ulp above the round-off of h (a few
  /// DBL_EPSILON times the diagonal), while an edge flagged flat bends the surface by
  /// less than 1e-9 of the mesh size, far below anything a contact can resolve.
  static constexpr Real kFlatEdgeRelTolerance = 1e-9;
  /// The absolute flat-edge tolerance used for this mesh (unit: m).
  Real flat_edge_tolerance() const { return flat_tolerance_; }
  const TriangleMeshBvh& bvh() const { return *bvh_; }

  Aabb local_aabb() const override { return aabb_; }
  bool is_solid() const override { return false; }

 private:
  std::vector<Vec3> vertices_;
  std::vector<std::array<int, 3>> triangles_;
  std::vector<Vec3> normals_;
  std::vector<std::array<int, 3>> neighbors_;
  std::vector<std::uint8_t> convex_edge_bits_;
  std::unique_ptr<TriangleMeshBvh> bvh_;
  Aabb aabb_;
  Real flat_tolerance_ = 0;
  bool one_sided_ = false;
};

/// A rigid set of convex children, each with a pose in the compound's frame.
class Compound final : public Shape {
 public:
  struct Child {
    std::shared_ptr<const ConvexShape> shape;
    Pose pose;
  };
  /// Throws InvalidArgument if empty or a child is null.
  explicit Compound(std::vector<Child> children);
  const std::vector<Child>& children() const { return children_; }
  Aabb local_aabb() const override { return aabb_; }
  bool is_solid() const override { return true; }
  /// Sum of the children's mass properties (parallel-axis theorem). Overlapping
  /// children are counted twice, as in Bullet and Jolt.
  MassProperties mass_properties(Real density) const override;

 private:
  std::vector<Child> children_;
  Aabb aabb_;
};

using ShapePtr = std::shared_ptr<const Shape>;

}  // namespace wmo
