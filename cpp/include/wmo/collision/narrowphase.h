// WMO collision layer: contact manifold generation for any pair of shapes.
//
// Conventions in wmo/types.h. Fast special routines `collide_<shape>_<shape>` work in
// A's frame (they take B's pose in A's frame); `collide` takes world poses, picks the
// routine from a [type][type] dispatch table (swapping A and B and flipping the result
// where only the mirrored routine exists), and returns world-space manifolds.
#pragma once

#include <vector>

#include "wmo/geometry/shapes.h"
#include "wmo/types.h"

namespace wmo {

struct CollideSettings {
  /// Speculative margin (unit: m): points with depth >= -margin are reported, so a
  /// pair closer than `margin` yields contacts with negative depth. 0 reports touching
  /// and overlapping pairs only.
  Real margin = 0;
  /// Use the fast special routines where they exist. False forces the generic
  /// GJK/EPA + clipping path (used by tests and benchmarks to compare the two) for
  /// every convex pair, sphere-sphere and box-box included. Plane-convex pairs always
  /// use collide_plane_convex: a plane has no support point, so GJK cannot take it.
  bool use_special_routines = true;
  /// Internal-edge handling for triangle meshes (collide_mesh_convex): contact normals
  /// that come from flat or concave (internal) mesh edges and vertices are replaced by
  /// the triangle's face normal, so shapes slide over a tessellated flat surface without
  /// catching on its edges. False keeps the raw per-triangle GJK/EPA normals; meant for
  /// tests and comparisons.
  bool remove_internal_edges = true;
  /// Contact history for triangle meshes (a world passes its contact cache):
  /// `touched_before(touched_context, t)` is +1 if the pair had a contact with triangle
  /// t at the caller's last step from its front, -1 from its back, 0 if none. A
  /// triangle whose edge neighbour the pair touched counts as touched from the same
  /// side (a body pushed through near an edge ends up behind the next triangle).
  ///  * One-sided meshes (TriangleMesh::one_sided): a shape wholly behind a triangle's
  ///    plane and apart from it is behind the solid's surface and gets no contact,
  ///    unless the pair touched the triangle: it was pushed through within one step,
  ///    and the contact pushes it back out through the front.
  ///  * Two-sided meshes: a touched triangle keeps the side it was touched from, so a
  ///    body pressed past the sheet's middle within one step (a thin plate under a box
  ///    landing on it) is pushed back, not out through the other side.
  /// Null (the default): no history, each triangle decides alone.
  int (*touched_before)(const void* touched_context, int triangle) = nullptr;
  const void* touched_context = nullptr;
  GjkSettings gjk{};
  EpaSettings epa{};
};

/// Appends the manifolds of A at `pose_a` against B at `pose_b` (world frame) to `out`:
/// none when apart (beyond the margin), one for a convex pair, one per touching
/// triangle or compound child for composite shapes. Returns kUnsupported (appending
/// nothing) for a pair no routine handles, e.g. plane-plane or mesh-mesh.
QueryStatus collide(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                    std::vector<Manifold>& out, const CollideSettings& settings = {});

/// True if collide() has a routine (special or generic) for this pair of types.
bool collide_supported(ShapeType a, ShapeType b);

// ---- Special routines, in A's frame. Each returns true and fills `m` (normal, count,
// points; child_a / child_b are left as they are) if the pair is within `margin`;
// false (m untouched) otherwise. The sphere / capsule / box and plane routines neither
// allocate nor make virtual calls (a hull is reached through the final class, so its
// calls are devirtualised). Feature ids of the round-shape routines are
// (feature of A << 8) | feature of B, with sphere 0, capsule 0 / 1 for the ends at
// y = -h / +h and 2 for its side, and for a box the Voronoi region code
// sum_i t_i 3^i (t_i = 0 inside the slab of axis i, 1 at +h_i, 2 at -h_i);
// collide_plane.cpp documents the plane-convex ids. collide_box_box and
// collide_hull_hull (SAT with a bias towards face axes, clipping, <= 4 points;
// hull-hull decides separation by GJK first) use their own ids: a face contact
// encodes (reference face, incident face, clip vertex), an edge contact the pair of
// edges (bit 31 set); the layout is in collision/clip.h. Their depth along a face
// axis may exceed the exact minimum translation distance by up to 5% + 1e-5 * size
// (the face bias keeps stacks from flipping between face and edge contacts). ----
bool collide_sphere_sphere(const Sphere& a, const Sphere& b, const Pose& b_in_a, Real margin, Manifold& m);
bool collide_sphere_box(const Sphere& a, const Box& b, const Pose& b_in_a, Real margin, Manifold& m);
bool collide_sphere_capsule(const Sphere& a, const Capsule& b, const Pose& b_in_a, Real margin, Manifold& m);
bool collide_capsule_capsule(const Capsule& a, const Capsule& b, const Pose& b_in_a, Real margin, Manifold& m);
bool collide_capsule_box(const Capsule& a, const Box& b, const Pose& b_in_a, Real margin, Manifold& m);
bool collide_box_box(const Box& a, const Box& b, const Pose& b_in_a, Real margin, Manifold& m);
/// Hull-hull keeps its edge-query scratch arrays in a per-thread workspace that grows
/// to the largest hulls seen: it allocates only while that happens, never once warm.
bool collide_hull_hull(const ConvexHull& a, const ConvexHull& b, const Pose& b_in_a, Real margin, Manifold& m);
/// Plane A against any convex shape B.
bool collide_plane_convex(const Plane& a, const ConvexShape& b, const Pose& b_in_a, Real margin, Manifold& m);

/// Generic convex pair: GJK (distance when apart) / EPA (when overlapping) on the cores
/// plus radii, then a manifold of up to 4 points by clipping the two supporting faces.
/// `status` (optional) receives GJK / EPA's status: kMaxIterations or kDegenerate mean
/// the depth is the best valid answer found, not a converged one (gjk.h).
bool collide_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                           const CollideSettings& settings, Manifold& m, QueryStatus* status = nullptr);

/// Triangle mesh A against convex B: BVH query, one manifold per touching triangle
/// (child_a = triangle index), with internal-edge correction. Appends to `out`.
/// Triangles are two-sided: B behind a triangle gets the back side's normal (-n).
/// Per triangle, GJK / EPA (triangle_convex) gives the normal; with
/// settings.remove_internal_edges, a normal that comes from a flat or concave edge or
/// vertex of the mesh (TriangleMesh::edge_is_convex) is replaced by the triangle's face
/// normal, and one past a convex edge's neighbour is clamped to that neighbour's normal
/// (collide_mesh.cpp states the rule). Points come from clipping B's supporting face
/// against the triangle (or the triangle against B's face), depths measured along the
/// manifold normal, reduced to at most 4; a triangle whose clipped manifold is empty
/// (B lies over a neighbour, not over it) reports nothing. Allocates nothing beyond
/// the growth of `out` (GJK / EPA use per-thread workspaces).
void collide_mesh_convex(const TriangleMesh& a, const ConvexShape& b, const Pose& b_in_a,
                         const CollideSettings& settings, std::vector<Manifold>& out);

}  // namespace wmo
