// wmo.World and wmo.Body (cpp/include/wmo/world/world.h). Thin: argument parsing,
// zero-copy state views and GIL release around step().
//
// Views: world.positions (N, 3), orientations (N, 4, x y z w), linear_velocities and
// angular_velocities (N, 3) are writable float64 views of the world's own storage.
// Each keeps that storage alive (a capsule holding its shared_ptr), so a view never
// dangles: after add_body grows the world past its capacity, an old view is a detached
// copy (re-read the property; World.reserve(n) avoids the growth); after remove_body
// its row count is stale. Re-read the property after adding or removing bodies.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <memory>
#include <optional>
#include <utility>

#include "common.h"
#include "wmo/world/world.h"

namespace wmo::bindings {

namespace {

/// A body as Python sees it: the world (kept alive) and the handle.
struct PyBody {
  py::object world;  // the Python World object
  BodyId id;
};

World& world_of(const PyBody& b) { return b.world.cast<World&>(); }

template <class T, int kCols>
py::array state_view(SharedArray<T>& arr, int rows) {
  static_assert(sizeof(T) == kCols * sizeof(double), "tightly packed rows of doubles");
  // The capsule owns a copy of the shared_ptr: the storage lives as long as the view.
  auto* keep = new std::shared_ptr<T[]>(arr.shared());
  py::capsule owner(keep, [](void* p) { delete static_cast<std::shared_ptr<T[]>*>(p); });
  double* data = rows > 0 ? reinterpret_cast<double*>(arr.data()) : nullptr;
  static double empty_dummy[1] = {0};
  return py::array_t<double>({static_cast<py::ssize_t>(rows), static_cast<py::ssize_t>(kCols)},
                             {static_cast<py::ssize_t>(kCols * sizeof(double)), static_cast<py::ssize_t>(sizeof(double))},
                             data ? data : empty_dummy, owner);
}

Real opt_real(const py::object& o, const char* field) {
  if (o.is_none()) return std::numeric_limits<Real>::quiet_NaN();
  try {
    return o.cast<Real>();
  } catch (const py::cast_error&) {
    throw py::type_error(std::string(field) + " must be a number or None");
  }
}

py::dict stage_dict(const StageProfile& p) {
  py::dict d;
  d["seconds"] = p.seconds;
  d["count"] = p.count;
  d["total_seconds"] = p.total_seconds;
  d["total_count"] = p.total_count;
  d["runs"] = p.runs;
  return d;
}

}  // namespace

void bind_world(py::module_& m) {
  py::class_<PyBody>(m, "Body", R"doc(
Handle of a body in a World (from World.add_body). It stays valid until the body is
removed; using it afterwards raises ValueError. ``index`` is the body's current row in
the world's state arrays (it changes when another body is removed).
)doc")
      .def_property_readonly("index", [](const PyBody& b) { return world_of(b).index_of(b.id); },
                             "Current row in the world's (N, ...) state arrays.")
      .def_property_readonly("slot", [](const PyBody& b) { return b.id.slot; })
      .def_property_readonly("generation", [](const PyBody& b) { return b.id.generation; })
      .def_property_readonly("valid", [](const PyBody& b) { return world_of(b).is_valid(b.id); },
                             "False once the body has been removed.")
      .def_property_readonly("kind", [](const PyBody& b) {
        World& w = world_of(b);
        return std::string(to_string(w.kind(w.index_of(b.id))));
      })
      .def_property_readonly("mass", [](const PyBody& b) {
        World& w = world_of(b);
        return w.mass(w.index_of(b.id)).mass;
      }, "Mass (kg); 0 for static and kinematic bodies.")
      .def_property_readonly(
          "shape",
          [](const PyBody& b) {
            World& w = world_of(b);
            return std::const_pointer_cast<Shape>(w.shape_ptr(w.index_of(b.id)));
          },
          "The body's shape (the same object that was added).")
      .def_property_readonly(
          "friction", [](const PyBody& b) { World& w = world_of(b); return w.friction(w.index_of(b.id)); },
          "Friction coefficient of the body (a pair combines two).")
      .def_property_readonly(
          "restitution", [](const PyBody& b) { World& w = world_of(b); return w.restitution(w.index_of(b.id)); },
          "Restitution coefficient of the body (a pair combines two).")
      .def_property_readonly(
          "linear_damping", [](const PyBody& b) { World& w = world_of(b); return w.linear_damping(w.index_of(b.id)); },
          "1/s.")
      .def_property_readonly(
          "angular_damping",
          [](const PyBody& b) { World& w = world_of(b); return w.angular_damping(w.index_of(b.id)); }, "1/s.")
      .def_property_readonly(
          "gravity_scale", [](const PyBody& b) { World& w = world_of(b); return w.gravity_scale(w.index_of(b.id)); },
          "Multiplies the world's gravity for this body.")
      .def_property_readonly(
          "center_of_mass",
          [](const PyBody& b) { World& w = world_of(b); return to_array(w.mass(w.index_of(b.id)).local_com); },
          "Centre of mass (m, shape frame); zeros for static and kinematic bodies.")
      .def_property_readonly(
          "inertia",
          [](const PyBody& b) { World& w = world_of(b); return to_array(w.mass(w.index_of(b.id)).inertia_local); },
          "Inertia tensor about the centre of mass (kg m^2, shape axes), (3, 3); zeros for "
          "static and kinematic bodies.")
      .def_property(
          "position", [](const PyBody& b) { return to_array(std::as_const(world_of(b)).positions()[world_of(b).index_of(b.id)]); },
          [](const PyBody& b, py::object v) { world_of(b).set_position(b.id, to_vec3(v, "position")); },
          "Shape-frame origin (m, world); a copy. Setting it validates the value.")
      .def_property(
          "orientation",
          [](const PyBody& b) { return to_array(std::as_const(world_of(b)).orientations()[world_of(b).index_of(b.id)]); },
          [](const PyBody& b, py::object q) { world_of(b).set_orientation(b.id, to_quat_xyzw(q, "orientation")); },
          "Unit quaternion (x, y, z, w); a copy. Setting it validates the value.")
      .def_property(
          "linear_velocity",
          [](const PyBody& b) { return to_array(std::as_const(world_of(b)).linear_velocities()[world_of(b).index_of(b.id)]); },
          [](const PyBody& b, py::object v) {
            world_of(b).set_linear_velocity(b.id, to_vec3(v, "linear_velocity"));
          },
          "Centre-of-mass velocity (m/s, world); a copy. Setting it validates the value.")
      .def_property(
          "angular_velocity",
          [](const PyBody& b) { return to_array(std::as_const(world_of(b)).angular_velocities()[world_of(b).index_of(b.id)]); },
          [](const PyBody& b, py::object w) {
            world_of(b).set_angular_velocity(b.id, to_vec3(w, "angular_velocity"));
          },
          "Angular velocity (rad/s, world); a copy. Setting it validates the value.")
      .def_property(
          "ccd",
          [](const PyBody& b) {
            World& w = world_of(b);
            return w.ccd(w.index_of(b.id));
          },
          [](const PyBody& b, bool on) { world_of(b).set_ccd(b.id, on); },
          "Continuous collision detection for this body (dynamic bodies only; the World's "
          "``ccd`` switch must be on too): it never passes through anything.")
      .def_property(
          "collision_group",
          [](const PyBody& b) {
            World& w = world_of(b);
            return w.collision_group(w.index_of(b.id));
          },
          [](const PyBody& b, int g) { world_of(b).set_collision_group(b.id, g); },
          "Collision group, 0..63 (see World.set_group_collision).")
      .def_property_readonly(
          "sleeping",
          [](const PyBody& b) {
            World& w = world_of(b);
            const int i = w.index_of(b.id);
            return w.kind(i) == BodyKind::kDynamic && !w.is_awake(i);
          },
          "True while the body's island sleeps.")
      .def("__eq__", [](const PyBody& a, const PyBody& b) { return a.world.is(b.world) && a.id == b.id; })
      .def("__hash__", [](const PyBody& b) { return py::hash(py::make_tuple(b.id.slot, b.id.generation)); })
      .def("__repr__", [](const PyBody& b) {
        const World& w = world_of(b);
        if (!w.is_valid(b.id)) return std::string("Body(removed)");
        const int i = w.index_of(b.id);
        return "Body(index=" + std::to_string(i) + ", kind='" + to_string(w.kind(i)) +
               "', position=" + repr_vec(w.positions()[i]) + ")";
      });

  py::class_<World>(m, "World", R"doc(
A rigid-body world. Units: metres, kilograms, seconds, radians.

Parameters
----------
gravity : (3,) m/s^2, default (0, -9.81, 0).
dt : step length (s), default 1/60.
substeps : soft-step substeps per step (default 4): more give stiffer contacts.
    contact_hertz is capped at a quarter of the substep rate, and soft contacts of f Hz
    hold a tower of N cubes of half-extent a only if (2 pi f)^2 > 4 g N^3 / (7.837 a)
    (Greenhill's criterion for a column under its own weight; 17 unit cubes at the
    default 36 Hz): tall stacks need more substeps (30 unit cubes need 83 Hz, so 6
    substeps; within 5 cm at substeps=8, contact_hertz=120).
iterations : velocity iterations per substep (default 1).
relax_iterations : relax passes per substep, alternately forward and backward over the
    contacts (default 2). They take the approach out of the velocities inelastically, so
    they are what damps a stack's sway; two do not converge over a tall chain: a kicked
    30-box tower (8 substeps, 120 Hz) sways for minutes, and comes to rest with 10.
energy_guard_passes : most relax passes added to a substep that left the bodies in
    contact with more kinetic energy than before the contact solve (default 0: off; 8
    takes back what the tests measured).
    Cached impulses of a contact that stopped an impact are applied again the next
    step, and the relax passes may not take them all back: a column of three spheres
    gained 1e-3 of its scene's energy in one step without the guard. A pass is added
    while the energy rose by more than energy_guard_tolerance and the last pass took
    some out; ``world.energy_guard_added_passes`` counts the passes added in the last step.
    Costs about 5% of the solve stage on boxes3000; off by default because the passes
    it adds while a tall stack settles set a load-stiffened 30-box tower swaying (6.8 cm
    against 1.5 cm).
energy_guard_tolerance : relative energy rise a substep may keep (default 1e-6: above
    the single-precision solver lanes' rounding).
block_solver : solve each contact pair's normal rows together (a small LCP per pair, on
    the scalar double-precision solver, about 4x the solve stage's time; default False). The
    passes treat a contact's points alike, so a perfectly stacked tower stays on its axis
    where the rows alone rock it; the springs are no stiffer: a kicked tower falls above
    the same height (17 unit boxes at the defaults).
centroid_rows : give each contact pair a centroid row before its point rows: one
    impulse at all its points that meets their targets on average, so the passes stop
    handing a contact's first point the whole correction and the opposite point the
    reaction, a torque that rocks stacks (default False). Like block_solver it keeps a
    perfectly stacked tower on its axis without stiffening the springs (a kicked tower
    falls above 17 unit boxes either way); it costs a fifth more time per pyramid step.
contact_hertz, contact_damping_ratio, contact_push_max : the soft contact spring
    (Hz, ratio, m/s), defaults 36, 10, 3 (chosen on the pyramid and boxes3000 together:
    see SolverSettings in contact_solver.h).
contact_max_sag : load-aware stiffness (m, default 0: off). A contact whose spring would
    sag more than this under the weight resting on it (estimated from what rests on what
    under gravity) is stiffened until it sags this much, so a stack's resistance to
    tilting grows with the weight that tilts it; the push-out speed is unchanged, and
    no contact gets stiffer than a quarter of the substep rate (the cap on
    contact_hertz). With 1e-3 (and centroid_rows) a 20-box tower sags 3.0 cm instead of
    7.6, and 30 boxes stand at substeps=8 and the default 36 Hz (they buckle without).
contact_static_hertz_scale : contacts with a static or kinematic body get this many
    times contact_hertz, under the same cap (default 2, as Box2D v3): the ground
    carries the whole pile.
restitution_threshold : approach speed (m/s) below which nothing bounces (default 1).
speculative_distance : contacts are made this close before touching (m, default 0.04).
speculative_motion : the margin also grows by this times the distance the pair's
    relative translation covers in one step, dt |v_b - v_a| (default 0: the fixed margin
    alone). 1 makes a fast body's contact exist before it reaches a surface, so the step
    stops it there instead of inside or behind it (no tunnelling through thin walls, and
    fast bodies meeting head-on collide), at the cost of more contacts for fast bodies
    and, as with any speculative contact, an occasional stop at a corner the body would
    have passed within the margin. Rotation is not covered.
speculative_motion_static : the same for pairs with a static or kinematic body only
    (default 1: a body reaching fixed geometry gets its contact in time, so it stops or
    bounces at the surface, not inside it, as Box2D v3 treats static geometry
    continuously by default; the larger of the two applies).
manifold_reuse_distance, manifold_reuse_angle : a touching pair whose relative pose
    moved less than this (m, default 1e-3) and this (rad, default 2 degrees) since its
    manifold was computed keeps that manifold, carried along with the bodies, depths
    measured anew (Jolt's body pair cache): a resting pile costs almost no narrowphase.
    0 recomputes every pair every step.
friction_combine, restitution_combine : 'multiply' (default for friction, Bullet's rule),
    'geometric_mean', 'max' (default for restitution), 'min' or 'average'.
gyroscopic : integrate the gyroscopic term (default False): rotations keep the world
    angular momentum and the kinetic energy (to rounding in free flight), so a spin
    about the intermediate axis flips; without it the angular velocity is constant in
    free flight (and a non-spherical body's energy changes as it turns).
threads : threads for the parallel stages, the caller's included (default 1): the
    narrowphase, and on a pile of at least 8,192 contact constraints the solver's
    passes. Results are bit-identical for any count.
sleeping : put resting islands to sleep (default True): an island whose bodies all move
    slower than sleep_linear_threshold (m/s, default 0.05) and sleep_angular_threshold
    (rad/s, default 2 deg/s) for time_to_sleep (s, default 0.5) sleeps and costs nothing
    until an awake or moving body overlaps it, a force, impulse or setter reaches one of
    its bodies, its velocities or pose are written in the state arrays, or one of its
    bodies is removed.
ccd : the world switch for continuous collision detection (default True); each body
    asks for it with ``add_body(..., ccd=True)`` (off by default), and only those pay.
    Two halves: a CCD body's pairs get speculative contacts covering their relative
    translation in the step (the solver stops it at the surface it approaches), and
    after the solve each fast CCD body is swept from its start to its end pose,
    rotation included (time of impact, conservative advancement), against static,
    sleeping and kinematic bodies, other fast CCD bodies (both moving) and the dynamic
    bodies the solver had no contact with; one that would overlap something by more
    than its allowance is put back at that time, an impulse stops the approach there,
    and the potential energy the move back gains comes out of its kinetic energy, so
    CCD never adds energy. CCD belongs to the fast body: a fast non-CCD body can pass
    through a slow CCD one. Last, a contact pair of a CCD body that may have ended the
    step overlapping by more than the allowance (a corner that swung in within the
    step: the solver's rows only see the points of the step's start) is collided again
    at the end poses: an overlap the step deepened past the allowance is pushed back to
    half of it, and a moving pair (faster than the sleep threshold: a column
    decelerating, a pile crushed) is held to 1.5 allowances, its approach stopped. The
    ``ccd`` stage of ``profile`` counts the bodies swept, ``ccd_hits`` those put back,
    ``ccd_projections`` the overlaps pushed apart.
ccd_motion_threshold : a CCD body is swept only in steps where its points move more
    than this fraction of its inner radius (half-thickness; default 0.5): slower
    bodies take the ordinary path. 0 sweeps every CCD body every step.
ccd_penetration : how far a CCD body may overlap another before it is put back or
    pushed apart, as a fraction of its inner radius (default 0.05).
broadphase : 'aabb_tree' (default: a dynamic tree of fattened boxes), 'sweep_and_prune'
    or 'brute_force' (the reference, O(N^2) a step). All three report the same pairs in
    the same order, so the choice changes what a step costs, never its result.

State arrays (world.positions, orientations, linear_velocities, angular_velocities)
are zero-copy, writable views; see the module notes on their lifetime.
)doc")
      .def(py::init([](py::object gravity, double dt, int substeps, int iterations, int relax_iterations,
                       double contact_hertz, double contact_damping_ratio, double contact_push_max,
                       double contact_max_sag,
                       double contact_static_hertz_scale, double restitution_threshold, double speculative_distance, double speculative_motion,
                       double speculative_motion_static,
                       double manifold_reuse_distance, double manifold_reuse_angle,
                       const std::string& friction_combine,
                       const std::string& restitution_combine, bool gyroscopic, bool sleeping,
                       double sleep_linear_threshold, double sleep_angular_threshold, double time_to_sleep,
                       int threads, bool ccd, double ccd_motion_threshold, double ccd_penetration,
                       bool block_solver, bool centroid_rows, int energy_guard_passes,
                       double energy_guard_tolerance, const std::string& broadphase) {
             WorldSettings s;
             s.broadphase = broadphase_from_string(broadphase, "broadphase");
             s.gravity = gravity.is_none() ? Vec3(0, -9.81, 0) : to_vec3(gravity, "gravity");
             s.dt = dt;
             s.substeps = substeps;
             s.iterations = iterations;
             s.relax_iterations = relax_iterations;
             s.energy_guard_passes = energy_guard_passes;
             s.energy_guard_tolerance = energy_guard_tolerance;
             s.block_solver = block_solver;
             s.centroid_rows = centroid_rows;
             s.solver.contact_hertz = contact_hertz;
             s.solver.damping_ratio = contact_damping_ratio;
             s.solver.push_max = contact_push_max;
             s.solver.max_sag = contact_max_sag;
             s.solver.static_hertz_scale = contact_static_hertz_scale;
             s.solver.restitution_threshold = restitution_threshold;
             s.speculative_distance = speculative_distance;
             s.speculative_motion = speculative_motion;
             s.speculative_motion_static = speculative_motion_static;
             s.manifold_reuse_distance = manifold_reuse_distance;
             s.manifold_reuse_angle = manifold_reuse_angle;
             s.friction_combine = combine_rule_from_string(friction_combine, "friction_combine");
             s.restitution_combine = combine_rule_from_string(restitution_combine, "restitution_combine");
             s.gyroscopic = gyroscopic;
             s.enable_sleep = sleeping;
             s.sleep_linear_threshold = sleep_linear_threshold;
             s.sleep_angular_threshold = sleep_angular_threshold;
             s.time_to_sleep = time_to_sleep;
             s.threads = threads;
             s.enable_ccd = ccd;
             s.ccd_motion_threshold = ccd_motion_threshold;
             s.ccd_penetration = ccd_penetration;
             return std::make_unique<World>(s);
           }),
           py::arg("gravity") = py::none(), py::arg("dt") = 1.0 / 60, py::arg("substeps") = 4,
           py::arg("iterations") = 1, py::arg("relax_iterations") = 2, py::arg("contact_hertz") = 36.0,
           py::arg("contact_damping_ratio") = 10.0, py::arg("contact_push_max") = 3.0,
           py::arg("contact_max_sag") = 0.0,
           py::arg("contact_static_hertz_scale") = 2.0,
           py::arg("restitution_threshold") = 1.0, py::arg("speculative_distance") = 0.04,
           py::arg("speculative_motion") = 0.0, py::arg("speculative_motion_static") = 1.0,
           py::arg("manifold_reuse_distance") = 1e-3,
           py::arg("manifold_reuse_angle") = 2 * kPi / 180,
           py::arg("friction_combine") = "multiply", py::arg("restitution_combine") = "max",
           py::arg("gyroscopic") = false, py::arg("sleeping") = true, py::arg("sleep_linear_threshold") = 0.05,
           py::arg("sleep_angular_threshold") = 2 * kPi / 180, py::arg("time_to_sleep") = 0.5,
           py::arg("threads") = 1, py::arg("ccd") = true, py::arg("ccd_motion_threshold") = 0.5,
           py::arg("ccd_penetration") = 0.05, py::arg("block_solver") = false,
           py::arg("centroid_rows") = false, py::arg("energy_guard_passes") = 0,
           py::arg("energy_guard_tolerance") = 1e-6, py::arg("broadphase") = "aabb_tree")
      .def(
          "add_body",
          [](py::object self, std::shared_ptr<Shape> shape, py::object position, py::object orientation,
             const std::string& kind, py::object mass, double density, double friction, double restitution,
             py::object linear_velocity, py::object angular_velocity, double linear_damping, double angular_damping,
             double gravity_scale, bool ccd, int collision_group, py::object center_of_mass, py::object inertia,
             py::object inertia_axes) {
            World& w = self.cast<World&>();
            BodyDef d;
            d.shape = std::move(shape);
            d.kind = body_kind_from_string(kind);
            if (!position.is_none()) d.position = to_vec3(position, "position");
            if (!orientation.is_none()) d.orientation = to_quat_xyzw(orientation, "orientation");
            d.mass = opt_real(mass, "mass");
            d.density = density;
            d.friction = friction;
            d.restitution = restitution;
            if (!linear_velocity.is_none()) d.linear_velocity = to_vec3(linear_velocity, "linear_velocity");
            if (!angular_velocity.is_none()) d.angular_velocity = to_vec3(angular_velocity, "angular_velocity");
            d.linear_damping = linear_damping;
            d.angular_damping = angular_damping;
            d.gravity_scale = gravity_scale;
            d.ccd = ccd;
            d.collision_group = collision_group;
            if (!center_of_mass.is_none()) d.center_of_mass = to_vec3(center_of_mass, "center_of_mass");
            if (!inertia.is_none()) {
              // (3,) principal moments, or a (3, 3) tensor taken as is.
              const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(inertia);
              if (a && a.ndim() == 2) {
                if (a.shape(0) != 3 || a.shape(1) != 3)
                  throw InvalidArgument("inertia must be 3 principal moments or a (3, 3) tensor, got shape (" +
                                        std::to_string(a.shape(0)) + ", " + std::to_string(a.shape(1)) + ")");
                for (int r = 0; r < 3; ++r)
                  for (int c = 0; c < 3; ++c) d.inertia_tensor(r, c) = a.at(r, c);
              } else {
                d.inertia = to_vec3(inertia, "inertia");
              }
            }
            if (!inertia_axes.is_none()) d.inertia_axes = to_quat_xyzw(inertia_axes, "inertia_axes");
            return PyBody{self, w.add_body(d)};
          },
          py::arg("shape"), py::arg("position") = py::none(), py::arg("orientation") = py::none(),
          py::arg("kind") = "dynamic", py::arg("mass") = py::none(), py::arg("density") = 1000.0,
          py::arg("friction") = 0.5, py::arg("restitution") = 0.0, py::arg("linear_velocity") = py::none(),
          py::arg("angular_velocity") = py::none(), py::arg("linear_damping") = 0.0, py::arg("angular_damping") = 0.0,
          py::arg("gravity_scale") = 1.0, py::arg("ccd") = false, py::arg("collision_group") = 0,
          py::arg("center_of_mass") = py::none(), py::arg("inertia") = py::none(), py::arg("inertia_axes") = py::none(),
          R"doc(
Adds a body and returns its Body handle. ``kind`` is 'dynamic' (default), 'static' or
'kinematic'. ``mass`` (kg) overrides ``density`` (kg/m^3); the inertia follows the shape.
Position (m) and orientation (x, y, z, w) place the shape's frame; velocities are of
the centre of mass (m/s, rad/s, world frame). ``ccd=True`` turns on continuous
collision detection for a dynamic body (see World). ``collision_group`` (0..63) is the
body's group for World.set_group_collision. ``center_of_mass`` (m, shape frame) overrides
the shape's centroid (the shape's inertia moves there); ``inertia`` gives the principal
moments (kg m^2) about it, along ``inertia_axes`` (a unit quaternion in the shape frame):
UsdPhysics' MassAPI; or the full (3, 3) tensor about it in the shape frame (symmetric,
taken bit for bit: ``Body.inertia`` of a saved body restores it exactly). Bad values raise ValueError naming the
field; the world is unchanged. Existing state views may detach (see World).
)doc")
      .def(
          "set_group_collision",
          [](World& w, int a, int b, bool enabled) { w.set_group_collision(a, b, enabled); }, py::arg("group_a"),
          py::arg("group_b"), py::arg("enabled"),
          "Whether bodies of collision groups group_a and group_b (0..63) collide (symmetric; "
          "all pairs of groups collide by default). A filtered pair gets no contact and no "
          "CCD sweep; filters cost nothing while none is set.")
      .def("group_collision", &World::group_collision, py::arg("group_a"), py::arg("group_b"),
           "True if bodies of the two groups collide.")
      .def(
          "set_pair_collision",
          [](World& w, const PyBody& a, const PyBody& b, bool enabled) {
            if (&a.world.cast<World&>() != &w || &b.world.cast<World&>() != &w)
              throw InvalidArgument("set_pair_collision: both bodies must belong to this world");
            w.set_pair_collision(a.id, b.id, enabled);
          },
          py::arg("body_a"), py::arg("body_b"), py::arg("enabled"),
          "Whether two bodies may collide (False filters the pair until enabled again or one "
          "of them is removed): UsdPhysics' FilteredPairsAPI.")
      .def(
          "pair_collision",
          [](World& w, const PyBody& a, const PyBody& b) { return w.pair_collision(a.id, b.id); },
          py::arg("body_a"), py::arg("body_b"), "False if the pair is filtered.")
      .def(
          "remove_body",
          [](World& w, const PyBody& b) {
            if (&b.world.cast<World&>() != &w) throw InvalidArgument("body belongs to another world");
            w.remove_body(b.id);
          },
          py::arg("body"), "Removes a body; its handle becomes invalid and the last body takes its row.")
      .def(
          "body",
          [](py::object self, int index) { return PyBody{self, self.cast<World&>().id_at(index)}; },
          py::arg("index"), "The Body in row ``index``.")
      .def("reserve", &World::reserve, py::arg("n"),
           "Reserves storage for n bodies so that adding up to n keeps state views attached.")
      .def(
          "step", [](World& w, int n) { w.step(n); }, py::arg("n") = 1, py::call_guard<py::gil_scoped_release>(),
          "Advances n steps of dt (the GIL is released). Checks the state arrays first "
          "wherever they may have been written (while a view of them is alive, and at the "
          "first step after the last is released): a non-finite value or a non-unit "
          "quaternion raises ValueError and nothing moves.")
      .def_property_readonly("positions", [](World& w) { return state_view<Vec3, 3>(w.shared_positions(), w.body_count()); },
                             "(N, 3) writable view: shape-frame origins (m).")
      .def_property_readonly("orientations",
                             [](World& w) { return state_view<Quat, 4>(w.shared_orientations(), w.body_count()); },
                             "(N, 4) writable view: unit quaternions (x, y, z, w).")
      .def_property_readonly(
          "linear_velocities", [](World& w) { return state_view<Vec3, 3>(w.shared_linear_velocities(), w.body_count()); },
          "(N, 3) writable view: centre-of-mass velocities (m/s).")
      .def_property_readonly(
          "angular_velocities", [](World& w) { return state_view<Vec3, 3>(w.shared_angular_velocities(), w.body_count()); },
          "(N, 3) writable view: angular velocities (rad/s, world frame).")
      .def_property_readonly("body_count", &World::body_count)
      .def("__len__", &World::body_count)
      .def_property_readonly("dt", [](const World& w) { return w.settings().dt; })
      .def_property_readonly("gravity", [](const World& w) { return to_array(w.settings().gravity); })
      .def_property_readonly("substeps", [](const World& w) { return w.settings().substeps; })
      .def_property_readonly("iterations", [](const World& w) { return w.settings().iterations; })
      .def_property_readonly(
          "settings",
          [](const World& w) {
            const WorldSettings& s = w.settings();
            py::dict d;
            d["gravity"] = to_array(s.gravity);
            d["dt"] = s.dt;
            d["substeps"] = s.substeps;
            d["iterations"] = s.iterations;
            d["relax_iterations"] = s.relax_iterations;
            d["energy_guard_passes"] = s.energy_guard_passes;
            d["energy_guard_tolerance"] = s.energy_guard_tolerance;
            d["block_solver"] = s.block_solver;
            d["centroid_rows"] = s.centroid_rows;
            d["contact_hertz"] = s.solver.contact_hertz;
            d["contact_damping_ratio"] = s.solver.damping_ratio;
            d["contact_push_max"] = s.solver.push_max;
            d["contact_max_sag"] = s.solver.max_sag;
            d["contact_static_hertz_scale"] = s.solver.static_hertz_scale;
            d["restitution_threshold"] = s.solver.restitution_threshold;
            d["speculative_distance"] = s.speculative_distance;
            d["speculative_motion"] = s.speculative_motion;
            d["speculative_motion_static"] = s.speculative_motion_static;
            d["manifold_reuse_distance"] = s.manifold_reuse_distance;
            d["manifold_reuse_angle"] = s.manifold_reuse_angle;
            d["friction_combine"] = std::string(to_string(s.friction_combine));
            d["restitution_combine"] = std::string(to_string(s.restitution_combine));
            d["gyroscopic"] = s.gyroscopic;
            d["sleeping"] = s.enable_sleep;
            d["sleep_linear_threshold"] = s.sleep_linear_threshold;
            d["sleep_angular_threshold"] = s.sleep_angular_threshold;
            d["time_to_sleep"] = s.time_to_sleep;
            d["threads"] = s.threads;
            d["broadphase"] = std::string(to_string(s.broadphase));
            d["ccd"] = s.enable_ccd;
            d["ccd_motion_threshold"] = s.ccd_motion_threshold;
            d["ccd_penetration"] = s.ccd_penetration;
            return d;
          },
          "Every constructor setting as a dict (a copy): ``wmo.World(**world.settings)`` makes "
          "an empty world with the same settings.")
      .def(
          "filtered_pairs",
          [](py::object self) {
            py::list out;
            for (const auto& [a, b] : self.cast<const World&>().filtered_pairs())
              out.append(py::make_tuple(PyBody{self, a}, PyBody{self, b}));
            return out;
          },
          "The body pairs filtered by set_pair_collision(a, b, False), as (Body, Body) tuples.")
      .def_property_readonly("step_count", &World::step_count)
      .def_property_readonly("reused_manifolds", &World::reused_manifold_count,
                             "Manifolds of the last step reused from the cache instead of recomputed "
                             "(see manifold_reuse_distance).")
      .def_property_readonly("sleeping", [](const World& w) { return w.settings().enable_sleep; },
                             "Whether resting islands are put to sleep.")
      .def_property_readonly("awake_count", &World::awake_dynamic_count, "Number of awake dynamic bodies.")
      .def_property_readonly("ccd", [](const World& w) { return w.settings().enable_ccd; },
                             "The continuous collision detection switch (see World).")
      .def_property_readonly("ccd_hits", &World::ccd_hit_count,
                             "Bodies the last step's ccd stage put back at a time of impact.")
      .def_property_readonly("energy_guard_added_passes", &World::energy_guard_pass_count,
                             "Relax passes the energy guard added in the last step (all substeps; "
                             "see the energy_guard_passes setting).")
      .def_property_readonly("ccd_projections", &World::ccd_projection_count,
                             "Overlaps the last step's ccd stage pushed apart (contact pairs of CCD "
                             "bodies left deeper than their allowance).")
      .def_property_readonly(
          "awake",
          [](const World& w) {
            py::array_t<bool> a(w.body_count());
            auto m = a.mutable_unchecked<1>();
            for (int i = 0; i < w.body_count(); ++i) m(i) = w.is_awake(i);
            return a;
          },
          "(N,) bool copy: awake dynamic and all kinematic bodies are True, static and sleeping False.")
      .def(
          "wake", [](World& w, const PyBody& b) { w.wake(b.id); }, py::arg("body"),
          "Wakes the body's island (nothing happens to an awake, static or kinematic body).")
      .def(
          "apply_impulse",
          [](World& w, const PyBody& b, py::object impulse, py::object point) {
            w.apply_impulse(b.id, to_vec3(impulse, "impulse"), to_vec3(point, "point"));
          },
          py::arg("body"), py::arg("impulse"), py::arg("point"),
          "Applies an impulse (N s, world) at a world point (m) to a dynamic body.")
      .def(
          "apply_force",
          [](World& w, const PyBody& b, py::object force, py::object point) {
            w.apply_force(b.id, to_vec3(force, "force"), to_vec3(point, "point"));
          },
          py::arg("body"), py::arg("force"), py::arg("point"),
          "Applies a force (N, world) at a world point (m) during the next step.")
      .def(
          "apply_torque", [](World& w, const PyBody& b, py::object torque) { w.apply_torque(b.id, to_vec3(torque, "torque")); },
          py::arg("body"), py::arg("torque"), "Applies a torque (N m, world) during the next step.")
      .def_property_readonly("contact_count", &World::contact_point_count,
                             "Contact points of the last step.")
      .def_property_readonly("max_penetration", &World::max_penetration,
                             "Deepest overlap (m, 0 if none) of the last step's contact pairs, "
                             "collided again at the bodies' current poses (one narrowphase pass over "
                             "the pairs per read; the ``contacts`` depths are the step's manifold "
                             "points moved with their bodies, which miss a corner that swung in).")
      .def("kinetic_energy", &World::kinetic_energy, "Kinetic energy of the dynamic bodies (J).")
      .def_property_readonly(
          "contacts",
          [](const World& w) {
            const std::vector<ContactInfo> cs = w.contacts();
            const auto n = static_cast<py::ssize_t>(cs.size());
            py::array_t<int> pairs({n, py::ssize_t(2)});
            py::array_t<double> point({n, py::ssize_t(3)}), normal({n, py::ssize_t(3)});
            py::array_t<double> depth(n), impulse(n);
            auto pr = pairs.mutable_unchecked<2>();
            auto pt = point.mutable_unchecked<2>();
            auto nr = normal.mutable_unchecked<2>();
            auto dp = depth.mutable_unchecked<1>();
            auto im = impulse.mutable_unchecked<1>();
            for (py::ssize_t i = 0; i < n; ++i) {
              pr(i, 0) = cs[i].body_a;
              pr(i, 1) = cs[i].body_b;
              for (int k = 0; k < 3; ++k) {
                pt(i, k) = cs[i].point[k];
                nr(i, k) = cs[i].normal[k];
              }
              dp(i) = cs[i].depth;
              im(i) = cs[i].normal_impulse;
            }
            py::dict d;
            d["bodies"] = pairs;
            d["point"] = point;
            d["normal"] = normal;
            d["depth"] = depth;
            d["normal_impulse"] = impulse;
            return d;
          },
          "Contact points of the last step as arrays: bodies (M, 2) rows, point (M, 3), normal "
          "(M, 3, from the first body to the second), depth (M,, m, > 0 overlapping), "
          "normal_impulse (M,, N s over the last substep).")
      .def_property_readonly(
          "profile",
          [](const World& w) {
            py::dict d;
            for (std::size_t k = 0; k < kStageNames.size(); ++k) d[kStageNames[k]] = stage_dict(w.profile()[k]);
            return d;
          },
          "Per-stage profile: {stage: {seconds, count, total_seconds, total_count, runs}} for "
          "the last step (seconds, count) and accumulated (total_*, runs = steps with work).")
      .def("__repr__", [](const World& w) {
        return "World(bodies=" + std::to_string(w.body_count()) + ", dt=" + repr_real(w.settings().dt) +
               ", substeps=" + std::to_string(w.settings().substeps) + ")";
      });
}

}  // namespace wmo::bindings
