// WMO world layer: bodies reached by handles, the step as named stages, and its profile.
//
// Storage: body state lives in dense structure-of-arrays (positions, orientations,
// linear and angular velocities), one row per body in insertion order; removing a body
// moves the last body into its row (swap-remove), so dense indices change only on
// removal. A BodyId {slot, generation} stays valid until its body is removed; using it
// afterwards throws InvalidArgument (never undefined behaviour).
//
// The step (World::step), each stage timed into the profile:
//   update_broadphase  move the proxies of bodies that can move (fattened AABBs)
//   find_pairs         overlapping proxy pairs (deterministic order)
//   narrowphase        contact manifolds (wmo::collide) with a speculative margin,
//                      matched to last step's points by feature id (warm starting)
//   solve              soft step: per substep integrate_velocities, warm start, solve,
//                      integrate_positions, relax (contact_solver.h); with no contacts
//                      only the integration runs
//   restitution        skipped when no contact has restitution
//   store_impulses     impulses kept for the next step's warm start
//   ccd                continuous collision detection for the fast bodies that ask for
//                      it (BodyDef::ccd): each is swept from its start to its end pose
//                      against everything near its path (time_of_impact, rotation
//                      included) and put back at its first contact; skipped when no
//                      body asks for it
// Units: metres, kilograms, seconds, radians; +y is not special (gravity is a vector).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "wmo/collision/broadphase.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/dynamics/body.h"
#include "wmo/dynamics/contact_solver.h"
#include "wmo/geometry/queries.h"
#include "wmo/world/flat_map.h"
#include "wmo/world/shared_array.h"
#include "wmo/world/thread_pool.h"

namespace wmo {

/// How a pair's friction or restitution is formed from the two bodies' values.
enum class CombineRule : std::uint8_t {
  kMultiply = 0,       ///< a * b (Bullet's friction rule)
  kGeometricMean = 1,  ///< sqrt(a * b) (Box2D's friction rule)
  kMax = 2,            ///< max(a, b) (Box2D's restitution rule, MuJoCo's friction)
  kMin = 3,
  kAverage = 4,        ///< (a + b) / 2 (PhysX's default)
};
/// The rule named `s` ("multiply", "geometric_mean", "max", "min", "average"); any other
/// name raises InvalidArgument naming `field` (the setting being parsed) and the value.
CombineRule combine_rule_from_string(const std::string& s, const char* field = "combine rule");
/// The broadphase named as to_string(BroadphaseType) names it ("aabb_tree",
/// "sweep_and_prune", "brute_force"); throws InvalidArgument naming `field` otherwise.
BroadphaseType broadphase_from_string(const std::string& s, const char* field = "broadphase");
const char* to_string(CombineRule r);
Real combine(CombineRule rule, Real a, Real b);

struct WorldSettings {
  Vec3 gravity = Vec3(0, -9.81, 0);  ///< unit: m/s^2, world frame
  Real dt = 1.0 / 60;                ///< unit: s, one step
  /// Substeps per step (soft step): more substeps make contacts stiffer and stacks
  /// steadier at a proportional cost.
  int substeps = 4;
  /// Velocity iterations (Gauss-Seidel passes with bias) per substep.
  int iterations = 1;
  /// Relax passes (without bias) per substep, alternately forward and backward over
  /// the constraints (symmetric Gauss-Seidel: the backward pass undoes the forward
  /// pass's bias towards the constraints it visits first). 2: the backward pass
  /// removes most of the pyramid's sideways creep (SolverSettings::contact_hertz).
  /// The relax passes take the approach out of the velocities inelastically, so they
  /// are what damps a stack's sway, and over a tall chain two are far from converged: a
  /// 30-box tower at 8 substeps and 120 Hz kicked at 1 cm/s still moves 17 mm over
  /// steps 5000-6000 with 2, 0.5 mm with 10 (10 boxes come to rest within 500 steps with
  /// 2; test_stability.py).
  int relax_iterations = 2;
  /// Most relax passes added to a substep whose passes left the bodies in contact with
  /// more kinetic energy than they had before the contact solve (0: none). Once the
  /// passes have converged, inelastic contacts can only take energy out (the relax
  /// solution is a projection of the velocities, which the cached impulses only start
  /// from), but a contact that stopped an impact carries its large impulse into the
  /// next step, and relax_iterations passes may not take it all back (measured: a
  /// column of three spheres gained 1e-3 of the scene's energy in one step). Passes are
  /// added one at a time while the energy, measured in the solver's metric (mass and
  /// the step's start inertia), is above its value before the solve by more than
  /// energy_guard_tolerance, and stop at a pass that takes nothing out: the rows'
  /// anchors turn with the bodies between the biased and the relax passes, and what
  /// that leaves (about 1e-9 of the energy a substep in the tests) is not theirs to
  /// remove. Costs one energy sum over the bodies in contact a substep, and the passes
  /// (boxes3000: about 0.2 ms of a 3.5 ms solve stage, 1142 passes in 600 steps, deepest
  /// overlap 0.048 -> 0.033 m). Off by default: the converged relax passes it adds
  /// while a tall stack settles set a load-stiffened 30-box tower (contact_max_sag,
  /// 8 substeps) swaying by 6.8 cm where it sways by 1.5 cm without them. 8 is the
  /// value the energy tests use.
  int energy_guard_passes = 0;
  /// Relative energy rise in a substep that the guard leaves (dimensionless). 1e-6:
  /// above the single-precision lanes' rounding (2^-24 relative per operation) and the
  /// turning anchors' share, so a converged substep adds no pass.
  Real energy_guard_tolerance = 1e-6;
  /// Solve each manifold's normal rows together (NormalRows::kBlock: a small LCP per
  /// contact pair, exact in one pass) instead of one row after another. The passes then
  /// treat a contact's points alike, so a perfectly stacked tower stays on its axis (the
  /// rows alone rock it: each contact's first point takes the correction, the opposite
  /// one the reaction) and an unkicked stiff 30-box tower (8 substeps, 120 Hz) is still
  /// to 1e-13 m where the rows keep it swaying 1.5 cm. They do not stiffen the springs: a
  /// kicked tower falls above the same critical height (17 unit boxes at the defaults,
  /// Greenhill's, SolverSettings::contact_hertz) and keeps swaying, its sway decaying
  /// over about 100 s (test_stability.py). The passes run on the scalar,
  /// double-precision solver, not WideContacts' 8-wide lanes: about 4x the solve
  /// stage's time (pyramid: 143 against 35 ms a step; `wmo bench pyramid
  /// --block-solver`). Off by default.
  bool block_solver = false;
  /// Give each manifold a centroid row before its point rows (centroid_row in
  /// contact_solver.cpp): one impulse increment at all its points that meets their
  /// targets on average, so the Gauss-Seidel passes stop handing each contact's first
  /// point the whole correction and its opposite point the reaction, a torque that
  /// rocks stacks. A perfectly stacked tower then stays on its axis (unkicked, even 28
  /// unit boxes at the defaults, an unstable equilibrium), and a stiff 30-box tower (8
  /// substeps, 120 Hz) sways less. It does not stiffen the springs: a kicked tower falls
  /// above the same critical height as with the rows alone (17 unit boxes at the
  /// defaults, SolverSettings::contact_hertz; test_stability.py). Off by default for its
  /// cost: a fifth more time per pyramid step (measured, median of 3 runs of 600 steps:
  /// 44.6 against 37.1 ms, 1.76x PyBullet's speed instead of 2.17x; `wmo bench pyramid
  /// --engines wmo,pybullet --repeats 3 [--centroid-rows]`).
  bool centroid_rows = false;
  SolverSettings solver{};
  /// Speculative margin at rest (unit: m): contacts are created for pairs closer than
  /// this plus the motion margin below.
  Real speculative_distance = 0.04;
  /// Motion margin (dimensionless, >= 0): a pair's speculative margin grows by this
  /// times the distance its bodies' relative translation covers in one step,
  /// dt |v_b - v_a|, and each body's broadphase box is swept along dt v. A contact then
  /// exists before the step in which the surfaces would meet, however fast they
  /// approach, and the soft step stops them at the surface instead of inside or behind
  /// it (speculative contacts, as in Box2D v3, Jolt and Rapier). Rotation is not
  /// covered: a linearised rotation overestimates how fast a point approaches (a spinning
  /// rod then stops at a wall it would have swept past), so rotational tunnelling is
  /// left to time of impact (issue 4). Like every speculative scheme it can stop a body
  /// that would have slid past a corner within the margin. Bodies at rest pay nothing,
  /// fast ones pay for their extra contacts: boxes3000 with 1.0 has 41% more contact
  /// points and a 30-50% dearer step for a deepest penetration of 0.59 m instead of
  /// 0.955 m (2 m boxes). Off (0) by default.
  Real speculative_motion = 0.0;
  /// Motion margin (dimensionless, >= 0) for pairs with a static or kinematic body:
  /// as speculative_motion, for those pairs only (the larger of the two applies). At 1
  /// (default) a dynamic body approaching fixed geometry gets its contact in the step
  /// before it would reach it, so it stops or bounces at the surface rather than inside
  /// it, as Box2D v3 treats static geometry continuously for every body by default.
  /// So that the pair is found in time, the broadphase box of a body that moves more
  /// than speculative_distance in a step (along some axis) is swept along dt v times
  /// the larger of the two margins (before, only speculative_distance
  /// fattened it, and a ball falling 0.47 m a step, 0.19 m above a thin floor at one
  /// step and below it at the next, was never paired with it and fell through; now it
  /// lands). Rotation within the step is not covered (ccd is). Scenes at rest pay
  /// nothing; boxes3000 pays only for its ground pairs (its step time unchanged within
  /// the noise). Without it a ball (e = 0.5)
  /// dropped from 1 m at dt 1/60 sinks 1.25 cm into the ground before its contact
  /// exists and rebounds 1.1% low (0.5% with it).
  Real speculative_motion_static = 1.0;
  /// Continuous collision detection, the world switch (BodyDef::ccd is the per-body
  /// one; both must be on). WMO uses both halves that Box2D v3, Jolt and Rapier use:
  ///  1. Speculative contacts: a pair with a CCD body gets a speculative margin that
  ///     covers its relative translation in the step (as speculative_motion = 1, for
  ///     those pairs only), and the broadphase boxes of CCD bodies and kinematic bodies
  ///     are swept along dt v. The solver then stops a fast body at the surface it
  ///     approaches, in the step it gets there, with the right velocity (a bounce
  ///     bounces): no lost time.
  ///  2. Time of impact (the `ccd` stage, after the solve): speculative contacts see
  ///     only the closest features at the step's start and not rotation, so a fast
  ///     body may still reach something else (a spinning rod, a body given its speed
  ///     within the step, a corner). Each fast CCD body (see ccd_motion_threshold) is
  ///     swept from its start pose to its end pose, rotation included, by conservative
  ///     advancement (time_of_impact) against the bodies near its path: static and
  ///     sleeping ones where they are, kinematic ones along their own motion, other
  ///     fast CCD bodies along their sweeps (both are put back, in rounds until they
  ///     agree), and other dynamic bodies at their end pose, but only those the solver
  ///     had no contact with: a pair in contact is the solver's (putting back one body
  ///     of a pile while its neighbours go on makes new overlaps; measured on boxes3000
  ///     with CCD on every box, 2.5 m instead of 0.7 m). A body that would overlap
  ///     anything by more than half its allowance (ccd_penetration), or deepen an
  ///     overlap it started with by more than a quarter of it (each triangle of a mesh
  ///     and each child of a compound on its own: ToiSettings::deepen_allowance), is put
  ///     back at the first time it does (Box2D v3's continuous step, extended to
  ///     rotation and to fast pairs), and an impulse there stops the approach (the pair's restitution above
  ///     the threshold), as the solver would at that contact. The potential energy the
  ///     move back gains is taken out of its kinetic energy: CCD never adds energy.
  ///  3. The shock pass (in the solve stage, after each substep's relax passes): a CCD
  ///     body faster than the restitution threshold that rests on another body (in
  ///     the order of support from static and kinematic bodies) has its approach to
  ///     that body taken out alone, as if the supporting body were fixed, bottom up, so
  ///     a falling column stops box by box in the substep its bottom is stopped instead
  ///     of driving into itself (20 boxes at 25 m/s: 0.22 m deep without it, 2.4 cm
  ///     with it). It only slows the supported body along the normal: it never adds
  ///     energy (world.cpp, shock_pass).
  ///  4. Overlap projection (the `ccd` stage, after the sweeps): the rows see a pair
  ///     through its manifold's points at the step's start, so a corner that swings
  ///     in within the step, or a column decelerating on its soft contacts, can leave
  ///     a pair overlapping far deeper than the rows report. Every contact pair of an
  ///     awake CCD body that can have overlapped by more than the allowance (its
  ///     overlap at the start plus the relative motion of the two bodies' points) is
  ///     collided again at the end poses; one deeper than the allowance that grew by
  ///     more than a quarter of it in the step is pushed back to half of it (or to
  ///     its depth at the start), and one deeper than 1.5 allowances while a body of
  ///     the pair moves (faster than sleep_linear_threshold: a decelerating column,
  ///     a pile crushed by what lands on it) back to that depth: along the normal
  ///     (translation, shared by inverse mass), its approach stopped by an impulse
  ///     at the manifold's centroid and the potential energy the push gains taken
  ///     out of the kinetic energy, in rounds over the contacts of the bodies pushed
  ///     (world.cpp, project_ccd_overlaps). A resting pair's sag stays the solver's.
  ///     A body is never pushed into static geometry it touches: its partner takes
  ///     the push (or, pinned too, the pair is left to the solver); a round ends
  ///     with the pairs with static geometry; and a push longer than the CCD
  ///     threshold is swept against static geometry and stopped there.
  ///     boxes3000 with CCD on every box: 0.39-0.52 m -> 0.076-0.092 m deepest
  ///     overlap (six runs, positions perturbed by 1e-7 m).
  ///  A fast non-CCD dynamic body can still pass through a slow CCD body: CCD belongs
  ///  to the body that moves fast.
  bool enable_ccd = true;
  /// A CCD body takes the CCD path in a step only when the distance its points can
  /// move in it, |com_end - com_start| + (angle turned) x (bounding radius about the
  /// centre of mass), exceeds this fraction of its inner radius (its half-thickness,
  /// wmo::inner_radius). Slower bodies cannot pass through anything in one step and
  /// take the ordinary path (0.5: Box2D's safety factor; 0 sweeps every CCD body).
  Real ccd_motion_threshold = 0.5;
  /// Penetration a swept CCD body may reach before it is put back, as a fraction of
  /// its inner radius (dimensionless, > 0): it is put back where it overlaps by between
  /// a quarter and a half of this (a contact then exists for the next step); a contact
  /// pair of a CCD body that the step left overlapping by more than this is pushed
  /// back to half of it, and a moving pair's overlap is held to 1.5 times it (overlap
  /// projection, 4. above). 0.05 on a box of half-extent 1 is 5 cm.
  Real ccd_penetration = 0.05;
  /// Broadphase fattening (unit: m): a body moves its proxy only when its box leaves
  /// the box fattened by this much.
  Real aabb_margin = 0.1;
  /// Manifold reuse (Jolt's body pair cache): a touching pair whose relative pose has
  /// moved less than this distance (unit: m) and this angle (unit: rad) since its
  /// manifold was computed keeps that manifold, its points carried along rigidly with
  /// the two bodies and its depths measured anew along the normal, instead of running
  /// the narrowphase again (Jolt's defaults). The depths stay exact for a contact whose
  /// features do not change (resting faces); the points' positions along the surface
  /// lag by up to distance + angle x body size (1.7 cm for a 1 m box at 2 degrees). A
  /// resting pile then costs little narrowphase (the pyramid: 99% of its manifolds
  /// reused, step about 25% cheaper). 0 for either recomputes every pair every step.
  Real manifold_reuse_distance = 1e-3;
  Real manifold_reuse_angle = 2 * kPi / 180;
  CombineRule friction_combine = CombineRule::kMultiply;
  CombineRule restitution_combine = CombineRule::kMax;
  /// Gyroscopic term w x (I w) for dynamic bodies: each substep's rotation keeps the
  /// world angular momentum (implicit midpoint on the rotation, see integrate_position)
  /// and the kinetic energy (a projection after it), so a free spinning body conserves
  /// both to rounding and shows the intermediate-axis flip, at any step (tested to one
  /// substep of 1/30 s for a 1:383 rod: the rotation is taken in parts where it turns
  /// fast or the inertia ratio is large). Off by default, as in Box2D and Bullet
  /// (without it, w is constant in free flight, which is what a sphere does and what
  /// games usually want).
  bool gyroscopic = false;
  /// The broadphase algorithm (collision/broadphase.h). Each reports the same pairs
  /// in the same order, so the choice changes the cost, never the result: the dynamic
  /// tree (the default) for scenes that move, sweep and prune where bodies are spread
  /// along one axis, brute force (O(N^2) a step) as the reference.
  BroadphaseType broadphase = BroadphaseType::kAabbTree;
  /// Threads for the step's parallel stages, the caller's included: the narrowphase,
  /// and on a pile of at least 8,192 contact constraints the solver's passes (its
  /// four regions at once, then the constraints between them; World::solve_order).
  /// Results are bit-identical for any count: work is split into fixed parts and
  /// joined in order, and the solver's regions do not depend on the count. 1 (the
  /// default) starts no thread.
  int threads = 1;
  /// Sleeping (Box2D v3's rule and thresholds): bodies connected by contacts form an
  /// island; when every body of an island has moved slower than both thresholds for
  /// `time_to_sleep`, the island sleeps: its velocities are zeroed and it costs nothing
  /// (no integration, broadphase update, contacts or solve) until something wakes it:
  /// an awake body or a moving kinematic body overlapping one of its bodies (broadphase
  /// boxes), a force, impulse or setter on one of its bodies, a velocity or pose written
  /// into its rows of the state arrays, or the removal of one of its bodies.
  bool enable_sleep = true;
  Real sleep_linear_threshold = 0.05;   ///< unit: m/s, of the centre of mass
  Real sleep_angular_threshold = 2 * 3.14159265358979323846 / 180;  ///< unit: rad/s (2 deg/s)
  Real time_to_sleep = 0.5;             ///< unit: s
};

/// Checks every setting and throws InvalidArgument naming the first bad one.
void validate_world_settings(const WorldSettings& s);

/// Handle of a body: `slot` indexes the world's handle table; `generation` changes when
/// the slot is reused, so a handle to a removed body is detected.
struct BodyId {
  std::int32_t slot = -1;
  std::uint32_t generation = 0;
  bool operator==(const BodyId&) const = default;
};

/// Time and work of one stage.
struct StageProfile {
  double seconds = 0;  ///< wall time of the stage in the last step
  long long count = 0;  ///< work items of the stage in the last step (see World::profile)
  double total_seconds = 0;  ///< accumulated over every step since the world was made
  long long total_count = 0;
  long long runs = 0;  ///< steps in which the stage did any work
};

/// A contact's overlap allowance as a fraction of the thinner moving body's thickness
/// (ContactConstraint::allow, World::overlap_allowance). A quarter: a body held to a
/// quarter of its thickness keeps three quarters in front of a sheet of no thickness,
/// margin for a substep's approach before the rows catch it. It only raises a bias that
/// the spring has not yet taken to push_max, which at the defaults it does from 17 cm of
/// overlap against a static body and 28 cm between moving ones: a unit box's 25 cm
/// allowance changes the push of moving pairs 25-28 cm deep and nothing else.
inline constexpr Real kOverlapAllowance = 0.25;

/// Names of the step's stages, in order.
inline constexpr std::array<const char*, 8> kStageNames = {
    "update_broadphase", "find_pairs", "narrowphase", "solve", "restitution", "store_impulses", "ccd",
    "update_sleep"};

/// One contact point as World::contacts reports it (world frame).
struct ContactInfo {
  int body_a = 0, body_b = 0;  ///< dense body indices
  Vec3 point = Vec3::Zero();   ///< midpoint of the two surface points, m
  Vec3 normal = Vec3::UnitY();  ///< from A to B
  Real depth = 0;              ///< > 0 overlapping, m
  Real normal_impulse = 0;     ///< N s, over the last step
};

class World {
 public:
  explicit World(const WorldSettings& settings = {});

  const WorldSettings& settings() const { return settings_; }
  /// Replaces the settings (validated first; the world is unchanged on error).
  void set_settings(const WorldSettings& s);

  /// Adds a body; validates `def` first (the world is unchanged on error).
  BodyId add_body(const BodyDef& def);
  /// Removes a body; its handle becomes stale. The last body takes its dense row.
  void remove_body(BodyId id);
  bool is_valid(BodyId id) const;
  /// Dense row of a body (changes when another body is removed). Throws if stale.
  int index_of(BodyId id) const;
  /// Handle of the body in dense row `index`.
  BodyId id_at(int index) const;
  int body_count() const { return positions_.size(); }
  /// The broadphase (read-only) and body `index`'s proxy in it: its tight box is the
  /// box update_broadphase last computed for the body (the shape's world box fattened
  /// by the speculative distance and swept by the step's predicted motion), for
  /// diagnostics and tests.
  const Broadphase& broadphase() const { return *broadphase_; }
  ProxyId proxy_of(int index) const { return proxies_[index]; }

  /// Advances the world by n steps of settings().dt. First checks the state arrays
  /// wherever the user may have written them (see below): a non-finite value or a
  /// non-unit quaternion throws InvalidArgument naming the array and row, and nothing
  /// moves.
  void step(int n = 1);

  // ---- State (structure of arrays, one row per body, dense order). Writable: the
  // next step reads what the user wrote (velocities of static bodies are ignored; an
  // orientation written by the user is normalised by the next step; a sleeping body
  // written to wakes). Storage is shared (shared_array.h) so that NumPy views never
  // dangle.
  //
  // Checking what was written reads every body's state at each step() (a quick test
  // made in the update_broadphase stage on the values it reads anyway, validate_state
  // for anything it flags: ~3-4 us per 1,000 bodies), so step() makes it only where a
  // write is possible: after any call of a writable accessor below (for good: the
  // caller may keep the reference and write at any time), while a view from the
  // shared_* accessors is alive, and at the first step() after the last one is
  // released. A world changed only through add_body, remove_body and
  // the validating setters skips it: its state is then what those calls and the steps
  // made, which the check would pass unchanged (tests compare both routes bit for
  // bit). ----
  SharedArray<Vec3>& positions() { state_writable_ = true; return positions_; }        ///< shape origin, m
  SharedArray<Quat>& orientations() { state_writable_ = true; return orientations_; }  ///< (x, y, z, w) in memory
  SharedArray<Vec3>& linear_velocities() { state_writable_ = true; return linear_velocities_; }    ///< COM, m/s
  SharedArray<Vec3>& angular_velocities() { state_writable_ = true; return angular_velocities_; }  ///< rad/s
  /// The writable arrays for a view that keeps a copy of the storage's shared_ptr
  /// (SharedArray::shared()) for as long as it can write, and no reference to the
  /// array (the Python module's NumPy arrays): step() checks the state while any such
  /// copy is held (the storage's use count above 1), and once after the last is
  /// released; no check for good, as the writable accessors above imply.
  SharedArray<Vec3>& shared_positions() { state_shared_ = true; return positions_; }
  SharedArray<Quat>& shared_orientations() { state_shared_ = true; return orientations_; }
  SharedArray<Vec3>& shared_linear_velocities() { state_shared_ = true; return linear_velocities_; }
  SharedArray<Vec3>& shared_angular_velocities() { state_shared_ = true; return angular_velocities_; }
  const SharedArray<Vec3>& positions() const { return positions_; }
  const SharedArray<Quat>& orientations() const { return orientations_; }
  const SharedArray<Vec3>& linear_velocities() const { return linear_velocities_; }
  const SharedArray<Vec3>& angular_velocities() const { return angular_velocities_; }
  /// Reserves room for n bodies, so adding up to n keeps existing views attached.
  void reserve(int n);

  /// Validating setters for one body's state (the arrays above are the unchecked,
  /// zero-copy route). Throw InvalidArgument naming the field for a stale handle, a
  /// non-finite value or a non-unit quaternion (kUnitQuatTolerance); the world is then
  /// unchanged. The position is of the shape's origin (m, world), the velocities of the
  /// centre of mass (m/s, rad/s, world); the orientation is renormalised.
  void set_position(BodyId id, const Vec3& position);
  void set_orientation(BodyId id, const Quat& orientation);
  void set_linear_velocity(BodyId id, const Vec3& v);
  void set_angular_velocity(BodyId id, const Vec3& w);

  BodyKind kind(int index) const { return kinds_[index]; }
  /// True for a dynamic body that is awake, and for every kinematic body; false for
  /// static and sleeping bodies.
  bool is_awake(int index) const { return awake_[index] != 0; }
  /// Number of awake dynamic bodies.
  int awake_dynamic_count() const;
  /// Wakes the body's island (no effect on an awake, static or kinematic body).
  void wake(BodyId id);
  const BodyMass& mass(int index) const { return masses_[index]; }
  const Shape& shape(int index) const { return *shapes_[index]; }
  /// The shape object itself (shared, never copied).
  const std::shared_ptr<const Shape>& shape_ptr(int index) const { return shapes_[index]; }
  Real linear_damping(int index) const { return linear_damping_[index]; }
  Real angular_damping(int index) const { return angular_damping_[index]; }
  Real gravity_scale(int index) const { return gravity_scale_[index]; }
  Real friction(int index) const { return frictions_[index]; }
  /// Continuous collision detection of a body (BodyDef::ccd).
  bool ccd(int index) const { return ccd_[index] != 0; }
  void set_ccd(BodyId id, bool on);
  /// Bodies the last step's ccd stage put back at a time of impact.
  int ccd_hit_count() const { return ccd_hits_; }
  /// Overlaps the last step's ccd stage pushed apart (project_ccd_overlaps).
  int ccd_projection_count() const { return ccd_projections_; }
  /// Relax passes the energy guard added in the last step, over all substeps
  /// (WorldSettings::energy_guard_passes).
  long long energy_guard_pass_count() const { return guard_passes_; }
  Real restitution(int index) const { return restitutions_[index]; }

  // ---- Collision filtering (BodyDef::collision_group). A filtered pair gets no contact,
  // no CCD sweep and does not wake the other's island; filters cost nothing while none
  // is set (the find_pairs stage skips the check). ----
  /// Collision group of the body in dense row `index`.
  int collision_group(int index) const { return groups_[index]; }
  /// Moves a body to another group (0..kMaxCollisionGroups-1; InvalidArgument otherwise).
  void set_collision_group(BodyId id, int group);
  /// Whether bodies of groups a and b collide (symmetric; a == b allowed). Throws
  /// InvalidArgument for a group outside 0..kMaxCollisionGroups-1.
  void set_group_collision(int a, int b, bool enabled);
  bool group_collision(int a, int b) const;
  /// Whether the two bodies may collide at all (both handles valid, distinct); a
  /// filtered pair stays filtered until enabled again or one body is removed.
  void set_pair_collision(BodyId a, BodyId b, bool enabled);
  bool pair_collision(BodyId a, BodyId b) const;
  /// Number of filtered body pairs.
  int filtered_pair_count() const { return static_cast<int>(filtered_pairs_.size()); }
  /// The filtered body pairs (set_pair_collision(a, b, false)), each once, in a fixed
  /// order (by handle slot): what a saved world must write to be restored.
  std::vector<std::pair<BodyId, BodyId>> filtered_pairs() const;

  /// Applies an impulse (N s, world) at a world point (m) to a dynamic body; other
  /// kinds ignore it. Applies a force / torque for the next step only.
  void apply_impulse(BodyId id, const Vec3& impulse, const Vec3& world_point);
  void apply_force(BodyId id, const Vec3& force, const Vec3& world_point);
  void apply_torque(BodyId id, const Vec3& torque);

  /// Contact points of the last step (after the solve).
  std::vector<ContactInfo> contacts() const;
  int contact_point_count() const;
  /// Manifolds of the last step reused from the cache (WorldSettings::manifold_reuse_distance).
  long long reused_manifold_count() const { return reused_manifolds_; }
  /// Deepest overlap (m, 0 if none) of the last step's contact pairs, collided again
  /// at the bodies' current poses (a narrowphase pass over the pairs per call; see
  /// world.cpp): the geometry's overlap, not contacts()' depths, which are the step's
  /// manifold points moved with their bodies.
  Real max_penetration() const;

  /// Per-stage profile of the last step (and accumulated), in kStageNames order.
  /// Counts: update_broadphase = moved bodies, find_pairs = candidate pairs,
  /// narrowphase = touching manifolds, solve = contact points, restitution = bouncing
  /// contacts, store_impulses = contact points, ccd = bodies swept (fast CCD bodies;
  /// 0 when no body asks for CCD: the stage is skipped), update_sleep = awake dynamic
  /// bodies considered (0 when sleeping is off: the stage is skipped).
  const std::array<StageProfile, kStageNames.size()>& profile() const { return profile_; }
  long long step_count() const { return step_count_; }

  /// Kinetic energy sum 1/2 m v^2 + 1/2 w.I w over dynamic bodies (J).
  Real kinetic_energy() const;

 private:
  struct Slot {
    std::int32_t index = -1;  // dense row, -1 when free
    std::uint32_t generation = 0;
  };
  struct CachedPoint {
    std::uint32_t feature_id;
    Real normal_impulse;
    /// Friction impulse as a world vector: the next step's tangent basis may differ
    /// (orthonormal_basis jumps where the normal's z changes sign, which a vertical
    /// normal does under the slightest tilt), so components would be applied along the
    /// wrong directions; the vector is projected onto the new basis instead.
    Vec3 tangent_impulse;
  };
  /// A pair's manifold as the narrowphase computed it, in the bodies' local frames,
  /// with B's pose relative to A at that time: reused while the relative pose stays
  /// within WorldSettings::manifold_reuse_distance / manifold_reuse_angle of it.
  struct ManifoldGeometry {
    bool valid = false;
    /// Set on a manifold that was reused: the cache keeps the geometry it was computed
    /// with, so the tolerances bound the drift from that computation, not from the last
    /// step's reuse.
    bool keep_cached = false;
    Vec3 rel_position = Vec3::Zero();  ///< B's origin in A's frame, m
    Quat rel_rotation = Quat::Identity();  ///< B's rotation relative to A
    Vec3 normal = Vec3::UnitY();       ///< A's frame
    int count = 0;
    std::array<Vec3, 4> point_a{};     ///< A's frame
    std::array<Vec3, 4> point_b{};     ///< B's frame
    std::array<std::uint32_t, 4> feature_id{};
    /// Mesh pairs: +1 if the convex body touched the triangle from its front, -1 from
    /// its back (CollideSettings::touched_before at the next step); 0 otherwise.
    std::int8_t mesh_side = 0;
  };
  struct CachedManifold {
    // The geometry first: collide_pair reads it (reuse test, anchors) before anything
    // else, so its lines are the first the prefetch brings.
    ManifoldGeometry geometry;
    std::uint64_t stamp = 0;  ///< the step (step_count + 1) that last wrote it
    int count = 0;
    std::array<CachedPoint, 4> points{};
  };

  int require(BodyId id, const char* what) const;
  /// Narrowphase output of one thread.
  struct NarrowphaseOut {
    std::vector<Manifold> manifolds;  // scratch of collide()
    std::vector<ContactConstraint> constraints;
    std::vector<ManifoldKey> keys;
    std::vector<ManifoldGeometry> geometry;  // per constraint
    /// Per constraint: the index of its cache entry if it had one (found in
    /// collide_pair; indices stay valid while entries are added), else -1, so
    /// store_impulses does not look it up again.
    std::vector<int> entries;
    long long reused = 0;  // manifolds taken from the cache
  };
  /// Contact constraints of one pair (slots sa < sb, rows a, b) appended to out.
  void collide_pair(int sa, int sb, int a, int b, Real margin, NarrowphaseOut& out) const;
  /// Cache key of a manifold: the two slots and the composite children (triangle or
  /// compound child indices, -1 for none), each kept whole (ManifoldKey).
  static ManifoldKey manifold_key(int sa, int sb, int child_a, int child_b) {
    return {(static_cast<std::uint64_t>(static_cast<std::uint32_t>(sa)) << 32) | static_cast<std::uint32_t>(sb),
            (static_cast<std::uint64_t>(static_cast<std::uint32_t>(child_a)) << 32) |
                static_cast<std::uint32_t>(child_b)};
  }
  /// Below this many pairs the narrowphase runs on the calling thread alone (waking
  /// the workers costs ~10 us).
  static constexpr std::size_t kMinParallelPairs = 64;
  /// Sorts the step's pairs from the top down (see world.cpp).
  void order_pairs_top_down();
  /// The solver's order of constraints_ (solve_order_, solve_starts_): their top-down
  /// sequence, split into regions when there are enough of them (see world.cpp).
  void solve_order();
  /// Unit tangential direction of the slip at manifold m (zero if below 1e-4 m/s).
  Vec3 sliding_direction(const Manifold& m, int a, int b, const Vec3& com_a, const Vec3& com_b) const;
  Real pair_motion_margin(int a, int b) const;
  Vec3 world_com(int i) const { return positions_[i] + orientations_[i] * masses_[i].local_com; }
  /// One substep of h seconds for the bodies in coupled_ (velocities: dynamic ones).
  void integrate_velocities(Real h);
  /// Moves the coupled bodies by a substep (integrate_position). A body whose inertia
  /// is anisotropic and that has turned more than 0.05 rad since the step began
  /// (inertia_follows_turn; kRowMassTurnSin2, the turn past which the rows re-evaluate
  /// their effective masses) gets the world inverse inertia of its new orientation in
  /// its state, listed in inertia_turned_ (the wide passes re-pack it): the contact rows
  /// then apply impulses through the inertia the body has, not the step's start's. A
  /// rod spinning at 170 rad/s (2.8 rad a step at 60 Hz) dropped on the ground gained
  /// up to 5.5 times its energy through the stale one (67,779 times at one substep):
  /// the passes are energy-consistent in the metric they use. Isotropic bodies (spheres,
  /// cubes) and slow turns keep the step's inertia: nothing changes for them.
  void integrate_positions(Real h);
  bool inertia_follows_turn(int i) const;
  /// All `substeps` substeps of step h for the bodies [begin, end), each a plain free
  /// body (awake, dynamic, in no contact, gravity only, centre of mass at its origin,
  /// no gyroscopic term), in place on the state arrays.
  void integrate_plain_run(int begin, int end, Real h, int substeps);
  /// One substep of awake dynamic body i, working state s, flags f.
  void integrate_velocity(int i, BodyState& s, std::uint8_t f, Real h) const;
  /// One substep of awake (dynamic or kinematic) body i; its centre of mass moves by
  /// h v_move (s.v for a body in contact, the substep's mean velocity for a free one).
  void integrate_position(int i, BodyState& s, std::uint8_t f, Real h, const Vec3& v_move);
  /// The overlap allowance of a contact between bodies a and b (m; ContactConstraint::
  /// allow): kOverlapAllowance of the moving bodies' smaller thickness, taken as twice
  /// the inner radius (geometry/queries.h: a box's smallest half-extent, a hull's
  /// distance from its points' mean to its nearest face plane), for a compound that of
  /// the touching child (child_a, child_b: a manifold's child indices; -1, which no
  /// compound manifold carries, leaves its thinnest child's). +inf if neither body
  /// moves.
  Real overlap_allowance(int a, int b, int child_a, int child_b) const;
  /// One step; with check_state, the state check of step() first (in update_broadphase).
  void run_step(bool check_state);
  /// The stage of that name; returns the count moved. With check_state, also the state
  /// check of step() (validate_state), on the values it reads anyway: a bad value
  /// throws, with the state unchanged.
  long long update_broadphase(bool ccd, bool check_state);
  /// The ccd stage (world.h, WorldSettings::enable_ccd); returns the bodies swept.
  int continuous_step();
  /// The ccd stage's last part: overlaps deeper than a CCD body's allowance that the
  /// solve left with the bodies it had contacts with, pushed apart (world.cpp);
  /// returns how many.
  int project_ccd_overlaps();
  /// time_of_impact of body a (motion ma) against body b (motion mb) over `duration`
  /// (s), stopping where an overlap would pass half of `allowance` (m), or deepen one
  /// the pair starts with by a quarter of it (world.cpp).
  ToiResult sweep_to_allowance(int a, const Motion& ma, int b, const Motion& mb, Real duration, Real allowance) const;
  /// An impulse at a world point (m) along a unit normal (from a to b) that stops the
  /// two bodies' approach there (with the pair's restitution above the threshold if
  /// `bounce`); see world.cpp.
  void stop_approach(int a, int b, const Vec3& point, const Vec3& normal, bool bounce);
  /// Takes the potential energy the ccd stage's move of body i by d (m) gains against
  /// gravity out of its kinetic energy (world.cpp).
  void take_potential_gain(int i, const Vec3& d);
  /// How far a CCD body may overlap another before the ccd stage acts (m): the
  /// fraction WorldSettings::ccd_penetration of its inner radius.
  Real ccd_allowance(int i) const;
  /// Orders the step's contacts for the CCD bodies' shock pass (world.cpp); returns
  /// how many it holds.
  int build_shock_order();
  /// Sets each contact's load (ContactConstraint::load) from the support graph under
  /// gravity (world.cpp).
  void estimate_loads();
  /// The shock pass over shock_order_ after a substep's relax passes (world.cpp).
  void shock_pass(Real inv_h);
  bool ccd_active() const { return settings_.enable_ccd && ccd_count_ > 0; }
  /// Checks the state arrays (the user may have written them): a non-finite value or
  /// a quaternion off unit by more than kUnitQuatTolerance throws InvalidArgument
  /// naming the array and row; a sleeping body written to wakes its island; a
  /// quaternion not unit to rounding is normalised. Returns true if it woke or
  /// normalised anything.
  bool validate_state();
  /// True while a shared_* view of the state storage is held (its use count above 1).
  bool state_views_held() const {
    return positions_.shared().use_count() > 1 || orientations_.shared().use_count() > 1 ||
           linear_velocities_.shared().use_count() > 1 || angular_velocities_.shared().use_count() > 1;
  }
  void wake_island(int island);
  void wake_row(int index);
  /// The update_sleep stage; returns the awake dynamic bodies after it.
  int update_sleep();
  bool moving(int i) const;
  /// A dynamic body that is awake: the only kind that integrates, joins islands and
  /// needs contacts.
  bool awake_dynamic(int i) const { return kinds_[i] == BodyKind::kDynamic && awake_[i] != 0; }

  WorldSettings settings_;
  std::unique_ptr<Broadphase> broadphase_;

  // Dense per-body arrays.
  SharedArray<Vec3> positions_;
  SharedArray<Quat> orientations_;
  SharedArray<Vec3> linear_velocities_;
  SharedArray<Vec3> angular_velocities_;
  // Where step() checks the state (see the State accessors): a writable accessor was
  // called (for good), a shared_* one since the last step or a view was held then.
  bool state_writable_ = false;
  bool state_shared_ = false;
  std::vector<int> sphere_declined_;  // update_broadphase scratch (keep_sphere_boxes)
  std::vector<BodyKind> kinds_;
  std::vector<BodyMass> masses_;
  std::vector<std::shared_ptr<const Shape>> shapes_;
  std::vector<Real> frictions_, restitutions_, linear_damping_, angular_damping_, gravity_scale_;
  std::vector<std::uint8_t> groups_;  ///< collision group per row
  /// Per group, the groups it collides with (bit j); all ones until filtered.
  std::array<std::uint64_t, kMaxCollisionGroups> group_masks_;
  /// Filtered body pairs by slots (smaller slot << 32 | larger), sorted.
  std::vector<std::uint64_t> filtered_pairs_;
  /// Some group mask is not all ones, or some pair is filtered: find_pairs checks.
  bool has_filters_ = false;
  bool collides(int slot_a, int slot_b) const;
  void update_has_filters();
  std::vector<Vec3> forces_, torques_;
  bool has_forces_ = false;  ///< some apply_force / apply_torque since the last step
  std::vector<ProxyId> proxies_;
  std::vector<std::int32_t> slot_of_;  // dense row -> slot
  // Sleeping, per dense row: awake flag (see is_awake), time below the thresholds (s),
  // and for a sleeping body its island (index into islands_) and the pose it fell
  // asleep at (a pose written into the arrays afterwards wakes it).
  std::vector<std::uint8_t> awake_;
  /// Flags of each body, so that the integration skips what a body does not need:
  /// traits_ (fixed when the body is added) and body_flags_ (the traits plus this
  /// step's flags, set at the start of the solve stage).
  enum BodyFlag : std::uint8_t {
    kInContact = 1,    ///< in at least one contact constraint this step
    kHasForce = 2,     ///< a force or torque was applied for this step
    kHasDamping = 4,   ///< nonzero linear or angular damping (trait)
    kComOffset = 8,    ///< centre of mass away from the body origin (trait)
    kGyroscopic = 16,  ///< gyroscopic term on and anisotropic inertia
    kIsotropic = 32,   ///< inertia a multiple of the identity (trait)
    kSphere = 64,      ///< the shape is a Sphere: its world box is centre +- radius (trait)
  };
  std::vector<std::uint8_t> traits_;
  // The energy guard's scratch (each coupled_ body's row, mass and world inertia at
  // the step's start; zero for static and kinematic bodies) and its count of added
  // relax passes in the last step.
  struct GuardBody {
    Mat3 inertia;
    Real mass;
    int row;
  };
  std::vector<GuardBody> guard_bodies_;
  long long guard_passes_ = 0;
  // CCD, per dense row: the flag (BodyDef::ccd), the shape's inner radius and its
  // bounding radius about the centre of mass (m); the number of flagged bodies; the
  // poses at the start of the step (kept for the flagged rows while CCD is active) and
  // the ccd stage's scratch.
  std::vector<std::uint8_t> ccd_;
  std::vector<Real> inner_radius_, outer_radius_;
  int ccd_count_ = 0;
  std::vector<int> ccd_rows_;  ///< rows with the flag (rebuilt when dirty)
  bool ccd_rows_dirty_ = false;
  int ccd_hits_ = 0;
  int ccd_projections_ = 0;
  std::vector<int> ccd_overlap_pairs_;  ///< contacts project_ccd_overlaps checks (constraints_)
  std::vector<Vec3> ccd_pushed_;               ///< per row: projection's displacement (m)
  std::vector<int> ccd_pushed_rows_;           ///< rows with a non-zero displacement
  std::vector<int> ccd_pushed_now_;            ///< rows pushed in the current round
  std::vector<int> ccd_pair_start_, ccd_pair_fill_;  ///< CSR of ccd_adjacent_pairs_ by row
  std::vector<int> ccd_adjacent_pairs_;              ///< each row's contacts (constraints_)
  std::vector<Manifold> ccd_manifolds_;        ///< collide()'s scratch
  std::vector<Vec3> start_positions_;
  std::vector<Quat> start_orientations_;
  struct Sweep {
    int body = -1;
    Motion motion;         ///< start pose -> end pose over the step (about the centre of mass)
    Aabb box;              ///< world box of everything the body's points pass through
    Real reach = 0;        ///< how far its points move over the step (m)
    Real time = kInf;      ///< earliest time of impact found (s); set to dt at the start
    int hit_body = -1;     ///< the body it hits then (dense row)
    Vec3 hit_normal = Vec3::Zero();  ///< unit, from this body to the other
    Vec3 hit_point = Vec3::Zero();   ///< world, m
  };
  std::vector<Sweep> sweeps_;
  std::vector<std::int32_t> sweep_of_;  ///< per row: index into sweeps_, or -1
  std::vector<int> sweep_order_;  ///< sweeps_ sorted by their boxes' min x
  std::vector<std::pair<int, int>> sweep_pairs_;  ///< swept pairs whose boxes overlap
  std::vector<Real> sweep_seen_, sweep_now_;  ///< ccd rounds' scratch
  std::vector<std::uint64_t> ccd_seen_pairs_;  ///< row pairs with a contact constraint
  std::vector<std::uint8_t> body_flags_;
  std::vector<int> coupled_;  ///< awake bodies in contact this step (the substep loops' bodies)
  std::vector<int> inertia_turned_;  ///< coupled bodies whose inv_inertia integrate_positions refreshed
  /// The shock pass's contacts (index into constraints_, supporting body first), in
  /// order of support depth; the contact graph (CSR: start, adjacency, fill cursor)
  /// and the breadth-first search over it.
  std::vector<std::array<int, 3>> shock_order_;
  // estimate_loads' scratch: per contact, per body, the supported bodies, CSR.
  std::vector<int> load_upper_, load_bodies_, load_start_, load_contacts_, load_fill_;
  std::vector<Real> load_cos_, load_total_cos_, load_carried_;
  std::vector<int> shock_adjacency_start_, shock_adjacency_, shock_fill_, support_depth_, shock_queue_;
  std::vector<Real> sleep_time_;
  std::vector<std::int32_t> sleep_island_;
  std::vector<Vec3> sleep_position_;
  std::vector<Quat> sleep_orientation_;
  // Sleeping islands: the slots of their bodies (slots survive swap-removal).
  std::vector<std::vector<std::int32_t>> islands_;
  std::vector<std::int32_t> free_islands_;
  std::vector<std::int32_t> island_parent_, island_of_root_;  // update_sleep scratch, per row
  std::vector<Real> sleep_scratch_;
  // This step's runs [begin, end) of plain free bodies (integrate_plain_run), which
  // update_sleep may pass over (see there); cleared at the start of every step.
  std::vector<std::pair<int, int>> plain_runs_;
  // Smallest |gravity_scale| of any body added so far (a bound: not raised by removals).
  Real min_abs_gravity_scale_ = kInf;
  // True when every awake dynamic body's sleep timer is 0 (set by update_sleep; new
  // and woken bodies start at 0, so they keep it true).
  bool awake_timers_zero_ = true;

  std::vector<Slot> slots_;
  std::size_t cache_kept_asleep_ = 0;  // cache entries kept for sleeping bodies at the last walk
  bool cache_woke_ = false;            // an island woke since that walk
  std::vector<std::int32_t> free_slots_;

  // Step scratch and contact cache.
  std::vector<ProxyPair> pairs_;
  std::vector<NarrowphaseOut> thread_out_;
  std::unique_ptr<ThreadPool> pool_;  ///< null with threads = 1
  std::vector<BodyState> states_;
  std::vector<ContactConstraint> constraints_;
  std::vector<ManifoldKey> constraint_keys_;
  std::vector<ManifoldGeometry> constraint_geometry_;  ///< per constraint, for the cache
  std::vector<int> constraint_entries_;  ///< per constraint (NarrowphaseOut::entries)
  /// The order the solver visits constraints_ in (solve_order), its regions' starts
  /// (empty: none), what region_band_order reads, and scratch.
  std::vector<int> solve_order_, solve_starts_, solve_region_, solve_scratch_;
  std::vector<Real> solve_coord_, solve_height_, solve_band_;
  std::vector<std::uint64_t> solve_bits_;
  WideContacts wide_;  ///< the solver's lane-grouped copy of constraints_ (contact_solver.h)
  // Scratch of order_pairs_top_down (kept to avoid allocating every step).
  std::vector<std::uint64_t> order_scratch_;
  std::vector<ProxyPair> pair_scratch_;
  FlatMap<CachedManifold, ManifoldKey> cache_;  ///< by manifold_key
  /// cos(manifold_reuse_angle / 2), set before each narrowphase (collide_pair's test).
  Real reuse_cos_half_ = 1;
  long long reused_manifolds_ = 0;

  std::array<StageProfile, kStageNames.size()> profile_{};
  long long step_count_ = 0;
};

}  // namespace wmo
