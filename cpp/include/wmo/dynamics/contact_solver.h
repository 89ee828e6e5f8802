// WMO dynamics layer: the contact solver.
//
// Soft step (Catto, "Solver2D" 2024 and Box2D v3's solver.c / contact_solver.c): the
// step is split into substeps; each substep integrates velocities, warm starts, solves
// the contacts with a soft position bias (a spring-damper of `contact_hertz`, twice
// that, under the same cap, against a body that does not move; damping ratio
// `damping_ratio`; its bias capped at `push_max` m/s), integrates positions, then
// relaxes (solves again without the bias, so the bias's velocity is not kept as
// energy; WMO runs two relax passes by default, the second backward over the
// constraints, where Box2D runs one).
// Restitution is applied once after the substeps. Contacts are not recomputed per
// substep: the current separation is updated from the bodies' position and rotation
// deltas, and the anchors are turned with their bodies about their centres of
// curvature (current_anchors), in the separation and in the velocity rows alike. (Box2D
// v3 turns them in the separation only; the rows then push at a point the body has
// turned away from, and a body rocking on one corner gained energy: +0.43 J in 17 s.
// Turning them as material points everywhere instead carried a spinning ball's anchor
// off its contact: hence the curvature.)
//
// Rows per contact point: one normal row (non-negative impulse) and two friction rows
// whose combined impulse is clamped to the Coulomb cone |lambda_t| <= mu lambda_n. A
// manifold with zero friction builds no friction rows (ContactConstraint::friction == 0
// skips them in every pass).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "wmo/math.h"

namespace wmo {

/// Per-body solver state: what the inner loops read and write (hot data).
struct BodyState {
  Vec3 v = Vec3::Zero();   ///< linear velocity of the COM, m/s, world
  Vec3 w = Vec3::Zero();   ///< angular velocity, rad/s, world
  Vec3 dp = Vec3::Zero();  ///< COM displacement since the step began, m, world
  Quat dq = Quat::Identity();  ///< rotation since the step began (world frame)
  Real inv_mass = 0;           ///< 1/kg; 0 for static and kinematic bodies
  /// Gravity acting on the body (m/s^2, world; zero for static and kinematic bodies):
  /// restitution extrapolates an approach speed with it (apply_restitution).
  Vec3 gravity = Vec3::Zero();
  /// World-space inverse inertia (1/(kg m^2)) at the step's start; World refreshes it
  /// after a substep for an anisotropic body that has turned far (World::integrate_positions).
  Mat3 inv_inertia = Mat3::Zero();
};

/// Spring-damper coefficients of a soft constraint for one substep (Box2D v3 b2Softness).
struct Softness {
  Real bias_rate = 0;      ///< 1/s: bias velocity per metre of penetration
  Real mass_scale = 1;     ///< scales the effective mass
  Real impulse_scale = 0;  ///< fraction of the accumulated impulse removed each pass
  /// h omega (2 zeta + h omega), dimensionless: mass_scale / impulse_scale, the
  /// spring's implicit stiffness per substep relative to the row's effective mass
  /// (0 for a rigid row). A row stiffened L times (SolverSettings::max_sag) uses
  /// mass_scale = L a2 / (1 + L a2), impulse_scale = 1 / (1 + L a2), bias_rate unchanged.
  Real a2 = 0;
  /// h omega^2 (1/s): the spring's stiffness per unit effective mass, times h. A row of
  /// effective mass m carrying a steady impulse lambda per substep sags by
  /// lambda / (m h omega^2) (derivation at stiffening()).
  Real h_omega2 = 0;
  /// The largest stiffening (stiffening()) the substep resolves: (cap / hertz)^2, with
  /// cap the quarter of the substep rate that contact_softness caps contact_hertz at.
  /// A row stiffened past it is a spring the substep cannot follow, and measured, it
  /// pumps: a 1 kg box under a 100 kg one was squeezed 0.7 m out, under 1000 kg shot
  /// away. 1 (no stiffening) where the spring is at the cap already.
  Real max_stiffening = 1;
};

/// Softness for a spring of `hertz` (Hz) and `damping_ratio` over a substep of h seconds.
Softness make_softness(Real hertz, Real damping_ratio, Real h);

/// The contacts' softness for one substep: `dynamic` between two moving bodies, `fixed`
/// for a contact with a body that does not move (inverse mass 0: static or kinematic),
/// which is stiffer (SolverSettings::static_hertz_scale).
struct ContactSoftness {
  Softness dynamic;
  Softness fixed;
};

struct ContactConstraintPoint {
  Vec3 ra = Vec3::Zero();  ///< anchor on A relative to A's COM at the step's start, m, world
  Vec3 rb = Vec3::Zero();  ///< anchor on B relative to B's COM, m, world
  /// Centres of curvature of A's and of B's surface at the point, as offsets along n
  /// from the anchors (m): A's is ra + ca_n n, B's rb + cb_n n (relative to each COM,
  /// world, at the step's start). World computes them from each body's own touching
  /// point moved into the body by its radius of curvature there (point_a - rho_a n,
  /// point_b + rho_b n), which lies on the normal through the anchor: a speculative
  /// contact's anchor sits in the gap, away from both bodies, and the offsets carry
  /// that. Each centre is taken as a material point that turns with its body while the
  /// touching point stays on the normal through it, so the anchors the rows use move
  /// with it within the step (current_anchors): for a vertex or an edge (rho 0) the
  /// point itself is material (a box corner: the row follows the corner); for a sphere
  /// it is the centre (a spinning ball's contact stays at its bottom).
  Real ca_n = 0, cb_n = 0;
  /// Separation at the step's start minus n.(rb - ra) (m), so that the current
  /// separation is adjusted_separation + n.((dp_b + rb') - (dp_a + ra')) with the
  /// current anchors ra', rb' (current_anchors).
  Real adjusted_separation = 0;
  /// 1 / (effective mass along n), kg, at the step's anchors (see row_mass for the
  /// turned ones).
  Real normal_mass = 0;
  std::array<Real, 2> tangent_mass{};  ///< same along the two tangents
  Real normal_impulse = 0;            ///< accumulated, N s (warm-started)
  std::array<Real, 2> tangent_impulse{};
  Real max_normal_impulse = 0;        ///< largest normal impulse this step (restitution)
  /// Normal relative velocity (m/s) at the step's start, replaced by the one at the
  /// substep where the point first pushes: the approach speed restitution reverses.
  Real relative_velocity = 0;
  /// Separation (m, >= 0 for a speculative contact) when the point first pushed: a
  /// speculative contact stops the bodies before their surfaces meet, so the approach
  /// speed at the meeting is relative_velocity extrapolated over this gap.
  Real push_gap = 0;
  /// Load stiffening of the normal row's spring (>= 1, dimensionless): its stiffness is
  /// this many times the softness's (stiffening(), SolverSettings::max_sag); set by
  /// prepare_contacts from its constraint's load (ContactConstraint::load), the same
  /// for every point of the constraint.
  Real stiffening = 1;
  std::uint32_t feature_id = 0;
};

struct ContactConstraint {
  int body_a = 0, body_b = 0;  ///< indices into the BodyState array
  Vec3 normal = Vec3::UnitY();  ///< from A to B, world
  /// Friction directions, unit, orthogonal to the normal and each other; set by the
  /// caller (the tangent impulses are components along them).
  Vec3 tangent1 = Vec3::UnitX(), tangent2 = Vec3::UnitZ();
  Real friction = 0;
  Real restitution = 0;
  /// The weight this contact carries (N), as estimated by its owner from the support
  /// graph (World: what rests on what under gravity), for the load stiffening of its
  /// normal rows (SolverSettings::max_sag); 0: none known, no stiffening.
  Real load = 0;
  /// Overlap allowance (m, > 0; +inf: none): past this overlap the biased rows push the
  /// excess out within the substep, bias min(bias_rate s, (s + allow) / h) under
  /// push_max, instead of by the spring alone. The spring's sag does not depend on a
  /// body's size, and where the substep is long it is deep (the spring is capped at a
  /// quarter of the substep rate, 7.5 Hz at dt 1/30 and one substep, where g / omega^2
  /// is 4.4 mm; more when pressed or landing), so a thin body could end wholly behind a
  /// sheet of no thickness (a two-sided mesh) and leave it (measured: a 4 mm plate
  /// resting on one sank 4.4 mm; now 1.3 mm). World sets it to kOverlapAllowance of
  /// the thinner moving body's thickness (World::overlap_allowance; kOverlapAllowance
  /// says what thick bodies feel of it).
  Real allow = kInf;
  int count = 0;
  std::array<ContactConstraintPoint, 4> points{};
};

struct SolverSettings {
  /// Hz, capped at a quarter of the substep rate. Stiffer springs sag less (steady
  /// penetration ~ load / (effective mass * (2 pi hertz)^2)) but make the Gauss-Seidel
  /// passes creep. The defaults (36 Hz, damping ratio 10, 2 relax passes forward and
  /// backward, static contacts 2x under the cap) were chosen on the 20-layer pyramid,
  /// boxes3000 and a 10-box tower together (issue 3; pyramid: largest displacement
  /// after 600 steps, "creep" its sideways part; boxes3000: deepest penetration over
  /// 600 steps, no CCD; tower: sideways drift of its top once settled):
  ///   Box2D v3's 30 Hz, ratio 10, 1 relax (the old defaults): pyramid 1.9 cm (1.1 cm
  ///     creep), boxes3000 0.66 m, tower 3.8 mm;
  ///   the same with static contacts 2x: pyramid 1.7 cm;
  ///   36 Hz, 2 relax passes both forward: pyramid 1.2 cm (1.0 cm creep); with ratio
  ///     1 or 2 instead of 10, 7.2 / 8.6 mm, but boxes3000 1.00 / 0.74 m (a lightly
  ///     damped contact stops a fast box later) and the tower rocks while it settles
  ///     and stays 1.1 cm off;
  ///   36 Hz, 2 relax passes forward then backward, ratio 10 (the defaults): pyramid
  ///     8.3 mm (2.1 mm creep; the same after 6000 steps, at rest), boxes3000 0.50 m,
  ///     tower 3.9 mm.
  /// 40 Hz and above crept again at 4 substeps then. Measured again since (the rows
  /// now follow the bodies' turns): at 60 Hz, the cap at 4 substeps, the pyramid moves
  /// 4.1 mm (at rest, the same after 6000 steps) and a 20-box tower stands, but from
  /// 54 Hz a 1000:1 heavy box on a light one squeezes the light one out (11-23 m),
  /// where 36 Hz keeps it under (0.27 m crush): the mass ratio keeps the default.
  /// The springs make a tower an elastic column: N cubes of half-extent a stand only
  /// above Greenhill's critical frequency, sqrt(4 g N^3 / (7.837 a)) / (2 pi) (each
  /// joint holds its tilt with four corner rows of effective mass m / 8): at 36 Hz up
  /// to 17 unit cubes, 30 need 83 Hz (test_stability.py, followed to a few percent).
  Real contact_hertz = 36;
  /// Contacts with a body that does not move (static or kinematic) get this many times
  /// contact_hertz, under the same cap (Box2D v3's static softness, 2): the ground
  /// carries a whole pile, and a spring of half the stiffness there sagged most of
  /// the pile's sag, where nothing on the other side can give way and the row's
  /// effective mass is that of one body.
  Real static_hertz_scale = 2;
  /// Of the contact spring (dimensionless; 1 is critical damping). 10, as Box2D v3:
  /// strongly over-damped, no bounce, and a fast box is stopped early (contact_hertz).
  Real damping_ratio = 10;
  Real push_max = 3;             ///< m/s, largest bias velocity that resolves overlap
  Real restitution_threshold = 1;  ///< m/s, slower approaches do not bounce
  /// Load-aware stiffness (m; 0 turns it off): a contact whose spring would sag more
  /// than this under the weight it carries (ContactConstraint::load) is stiffened
  /// until it sags this much (stiffening()). The spring's stiffness is its effective
  /// mass times (2 pi hertz)^2: the mass of the two bodies at the contact, not of what
  /// they carry, so a tall stack's lower contacts hold the weight of everything above
  /// them on springs as soft as the top's, sag in proportion (a 30-box tower of unit
  /// boxes: 17 cm in all), and hold the stack's tilt with those springs alone: the
  /// stack buckles like an elastic column under its own weight once its height cubed
  /// outgrows their stiffness (30 boxes at 36 Hz fall by step ~600). Stiffened, each
  /// contact's stiffness follows its load (load / max_sag), so the resistance to
  /// tilting grows with the weight that tilts it. The bias rate (how fast an overlap is
  /// pushed out) is unchanged: a stiffened row is a rigid row with the spring's gentle
  /// position correction, not a harder push, and never stiffer than the substep
  /// resolves (Softness::max_stiffening: a 30-box tower needs 8 substeps for enough of
  /// it; a 20-box one sags 3.0 cm instead of 7.6 at 4). The load is the weight from the support
  /// graph, not the impulse the contact carried: stiffness set from the impulse feeds
  /// back on itself (a stiffer contact pushes harder, carries more, gets stiffer;
  /// measured, a 20-box tower then rocks by up to 2.5 m). Lightly loaded contacts (a
  /// box resting alone sags 0.07-0.4 mm at the defaults, whatever its size) keep their
  /// softness.
  Real max_sag = 0;
};

/// The stiffening factor (>= 1) of a normal row of effective mass `normal_mass` (kg)
/// that carried `impulse` (N s) per substep, for max_sag (m). A soft row at rest (vn =
/// 0) with penetration s changes its impulse by -m mass_scale bias_rate s -
/// impulse_scale lambda, zero at s = -lambda / (m a2 bias_rate) = -lambda / (m h
/// omega^2): that is the sag. Above max_sag the row's stiffness is multiplied by sag /
/// max_sag (Softness::a2), which brings the sag down to max_sag, but never past what
/// the substep resolves (Softness::max_stiffening). 1 where the row is rigid, carried
/// nothing or max_sag is 0.
inline Real stiffening(const Softness& soft, Real max_sag, Real normal_mass, Real impulse) {
  if (!(max_sag > 0) || !(soft.h_omega2 > 0) || !(normal_mass > 0) || !(impulse > 0)) return 1;
  const Real sag = impulse / (normal_mass * soft.h_omega2);
  return sag > max_sag ? std::min(sag / max_sag, soft.max_stiffening) : 1;
}

/// The anchors of point p at the bodies' current motion (dq since the step began): each
/// moves as its body's centre of curvature at the point does (ContactConstraintPoint::ca_n),
/// ra' = ra + (dq_a ca - ca) with ca = ra + ca_n n, likewise rb'. A vertex is carried as a
/// material point; a sphere centred on its centre of mass keeps its anchor. Both the
/// separation and the velocity rows use these, so the rows push at the point whose
/// separation they correct.
void current_anchors(const BodyState& a, const BodyState& b, const ContactConstraintPoint& p, const Vec3& n,
                     Vec3& ra, Vec3& rb);

/// Separation (m) of point p now: at the step's start plus the bodies' motion since,
/// at the current anchors ra, rb (turned with the bodies, see current_anchors).
inline Real separation_now(const BodyState& a, const BodyState& b, const ContactConstraintPoint& p, const Vec3& n,
                           const Vec3& ra, const Vec3& rb) {
  const Vec3 d = (b.dp + rb) - (a.dp + ra);
  return n.dot(d) + p.adjusted_separation;
}

/// Turns since the step began up to this (sin^2 of half the angle: 0.05 rad) keep the
/// step's effective masses outright (row_mass), without evaluating the turned ones.
constexpr Real kRowMassTurnSin2 = 6.25e-4;

/// The effective-mass inverse a row uses at the turned anchors: the step's (`stale`,
/// from prepare_contacts) while neither body has turned by more than 0.05 rad since the
/// step began (`turn_sin2`: the larger sin^2 of half their angles) or while it is
/// within 10% of the one at the current anchors (`current`), else the current one;
/// 0 (a padding point) stays 0. Recomputing it every pass made the 20-layer pyramid
/// creep (1.0 cm after 3000 steps against 8.2 mm; 5.6 mm of motion after step 600
/// against none), while a body that turns far within a step (a box spinning 100
/// degrees a step) needs it: with the stale mass its pushes overshoot and diverge.
/// Within 10% a Gauss-Seidel row under- or overshoots by at most 10%, which the passes
/// absorb.
inline Real row_mass(Real stale, Real current, Real turn_sin2) {
  if (turn_sin2 <= kRowMassTurnSin2 || stale == 0) return stale;
  return std::abs(stale - current) <= 0.1 * current ? stale : current;
}

/// The contacts' softness for the substep `h` (s), from the settings' spring.
ContactSoftness contact_softness(const SolverSettings& s, Real h);
/// Computes effective masses and approach velocities for the scalar passes, and the
/// softness for `h` (the substep). States must hold inv_mass / inv_inertia;
/// constraints their normal and tangents. (WideContacts::build computes the same for
/// its passes.)
void prepare_contacts(std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                      const SolverSettings& s, Real h, ContactSoftness& soft);
/// Applies the accumulated (warm-start) impulses.
void warm_start_contacts(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states);
/// How solve_contacts treats a constraint's normal rows (its 1 to 4 points).
enum class NormalRows : std::uint8_t {
  /// One row after another, each clamped on its own (projected Gauss-Seidel within the
  /// manifold, as WideContacts' passes do).
  kSequential,
  /// All of a manifold's rows at once: the linear complementarity problem of its
  /// points (solve_normal_block in contact_solver.cpp), so that one pass leaves the
  /// manifold's normal velocities exactly at their targets (Box2D v2's block solver
  /// for two points, here for up to four). Friction rows stay sequential.
  kBlock,
};

/// One Gauss-Seidel pass over every contact; `use_bias` adds the soft position bias.
/// `reverse` visits the constraints last to first (the relax passes alternate, as
/// WideContacts::solve's `reverse`).
/// `centroid_rows` runs each manifold's centroid row before its point rows
/// (kSequential only; centroid_row in contact_solver.cpp, WorldSettings::centroid_rows).
void solve_contacts(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states,
                    const ContactSoftness& soft, Real inv_h, Real push_max, bool use_bias,
                    NormalRows normal_rows = NormalRows::kSequential, bool reverse = false,
                    bool centroid_rows = true);
/// Restitution pass after the substeps (Box2D v3 b2ApplyRestitution): each point that
/// approached faster than `threshold` and pushed gets the normal velocity
/// -restitution * v_impact, where v_impact is the approach speed at the substep it first
/// pushed, extrapolated over the gap left then (push_gap) under the bodies' relative
/// gravity: v_impact^2 = v^2 + 2 g_n gap. (A speculative contact stops the bodies up to
/// a substep before their surfaces would meet, at a speed lower by up to a substep of
/// gravity: measured 3.6% low on e^2 h for e = 0.8 at dt 1/60 without it.)
void apply_restitution(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states,
                       Real threshold);

/// Writes to `order` the indices of `cs` level by level: a constraint's level is one
/// more than the last level used by either of its dynamic bodies (inv_mass > 0 in
/// `states`), stable within a level. Within a level no two constraints share a dynamic
/// body, and for every body the constraints acting on it keep their order, so Gauss-
/// Seidel passes in this order compute exactly what passes in the given order compute
/// (constraints with no dynamic body in common commute; static and kinematic bodies
/// receive exact zeros), while neighbours in it are independent: the order that fills
/// WideContacts' groups. `scratch` is reused storage. O(constraints + bodies).
void dependency_level_order(const std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                            std::vector<int>& order, std::vector<int>& scratch);

/// Writes to `order` the indices of `cs` region by region, for passes that run the
/// regions on several threads: `region[k]` (0 .. regions) is constraint k's region,
/// where regions 0 .. regions - 1 must share no dynamic body (the caller partitions the
/// bodies and gives a constraint the region of its dynamic bodies) and `regions` is the
/// boundary, the constraints whose dynamic bodies lie in different regions, last.
/// `starts` receives regions + 2 offsets: region r is order[starts[r], starts[r + 1]),
/// the boundary order[starts[regions], end).
///
/// Within a region (and the boundary) the constraints, which must come sorted by
/// height, highest first (World's top-down sequence), are cut into bands of
/// near-equal height and coloured within each band: `height[k]` is constraint k's
/// height (m, along up) and `band[k]`, for the constraint that opens a band, how far
/// below it others may lie and still join it (m). Each takes the lowest colour (0..63)
/// that no earlier constraint of its band with one of its dynamic bodies has; the
/// order is band by band, colour by colour, stable within a colour. So a stack's
/// layers keep the top-down order that carries its weight to the ground within one
/// Gauss-Seidel pass, while within a layer the constraints of one colour share no
/// dynamic body and fill WideContacts' groups. (A region in the exact sequence's
/// dependency levels, whose levels on a wide pile hold a few constraints each, left
/// the pyramid's groups a fifth emptier.) `scratch` is reused storage.
/// O(constraints log constraints + bodies).
void region_band_order(const std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                       const std::vector<int>& region, int regions, const std::vector<Real>& height,
                       const std::vector<Real>& band, std::vector<int>& order, std::vector<int>& starts,
                       std::vector<std::uint64_t>& scratch);

/// Threads for WideContacts' passes (World's ThreadPool implements it): run(fn) calls
/// fn(t) for every t in [0, size()) concurrently, t = 0 on the calling thread, and
/// returns when all have returned.
class ParallelTeam {
 public:
  virtual ~ParallelTeam() = default;
  virtual int size() const = 0;
  virtual void run(const std::function<void(int)>& fn) = 0;
};

/// The contacts regrouped for the solver's passes: groups of kLanes (8) constraints with
/// no dynamic body in common, stored lane by lane (structure of arrays), so each pass
/// runs one group's rows for all its lanes at once in 8-wide single-precision
/// arithmetic (AVX2 where the processor has it, chosen at run time; two 4-wide halves
/// otherwise: Box2D v3's "wide" solver). The groups are formed from consecutive
/// constraints in the given order, a new group starting whenever the next constraint
/// shares a dynamic body with the current group: the constraints in a group commute,
/// so the passes compute what the plain Gauss-Seidel passes (solve_contacts) over that
/// order compute, up to rounding (World passes its constraints by dependency level,
/// an order equivalent to its sequence that keeps the groups full). Missing lanes and
/// points are padding with zero mass.
///
/// Precision: the passes work in float (24-bit mantissa, 6e-8 relative) on quantities
/// that are all relative to the bodies (velocities, anchors from the centres of mass,
/// the motion since the step began, separations), never on positions, so a scene far
/// from the origin loses nothing. The separation is carried as its value at the step's
/// start plus the change the motion makes (n.(dp_b + (dq_b - 1) rb - dp_a - (dq_a - 1)
/// ra)), not as a large offset cancelled by large anchors. The bodies' double
/// velocities receive the float passes' velocity *changes*, so a body no impulse
/// touched keeps its velocity bit for bit.
class WideContacts {
 public:
  static constexpr int kLanes = 8;
  /// Packs `cs` for `states`, visiting the constraints in `order` (indices into cs,
  /// each once; the groups follow it); `dummy` is the index of a state with zero
  /// velocities and zero inverse mass and inertia that padding lanes point at. Computes
  /// what prepare_contacts computes for the scalar passes (each point's effective
  /// masses and approach velocity, from the states' masses and velocities) lane by
  /// lane, so `cs` needs no prepare_contacts; unpack writes the normal masses back.
  /// `soft`, `max_sag` and the substep `h` (s) give each constraint's points their
  /// stiffening (SolverSettings::max_sag) from its load, as prepare_contacts does; the
  /// defaults leave every point at 1. `centroid_rows` prepares the centroid rows (each
  /// set_motion then computes what they read); solve may run them only if it is set.
  /// `starts` (optional, from region_band_order): offsets into `order` where a region
  /// begins, the last one the boundary's; no group spans two regions, and with a team
  /// (set_team) the regions run at once (see there).
  void build(const std::vector<ContactConstraint>& cs, const std::vector<int>& order,
             const std::vector<BodyState>& states, int dummy, const ContactSoftness& soft = {},
             Real max_sag = 0, Real h = 0, bool centroid_rows = true, const std::vector<int>& starts = {});
  /// Reads the bodies' motion since the step began (dp, dq) from `states` and sets what
  /// the passes read of it: each point's anchors turned with the bodies
  /// (current_anchors), its separation now and its effective mass (row_mass). build()
  /// calls it; call it again whenever the motion changes (after integrate_positions).
  /// The motion changes only between passes, so the passes share the turned anchors
  /// instead of each turning them (a third of a pass's arithmetic).
  void set_motion(const std::vector<BodyState>& states);
  /// Re-reads the world inverse inertia (BodyState::inv_inertia) of `bodies` (state
  /// indices; ones the constraints do not use are ignored) into the lanes that hold
  /// them. build() packs each body's inertia once; World refreshes the inertia of an
  /// anisotropic body that has turned far within the step (World::integrate_positions)
  /// and calls this before set_motion, so that the passes' impulses and effective masses
  /// use the inertia the body has now.
  void refresh_inertia(const std::vector<BodyState>& states, const std::vector<int>& bodies);
  /// The passes of contact_solver.h on the packed contacts, at the motion of the last
  /// set_motion: each reads the bodies' velocities (v, w) from `states` and adds the
  /// velocity changes back.
  void warm_start(std::vector<BodyState>& states);
  /// `reverse` visits the groups last to first (a backward Gauss-Seidel pass).
  /// `centroid_rows`: each manifold's centroid row before its point rows, as
  /// solve_contacts (only if build prepared them).
  void solve(std::vector<BodyState>& states, const ContactSoftness& soft, Real inv_h, Real push_max,
             bool use_bias, bool reverse = false, bool centroid_rows = true);
  /// Writes impulses, max_normal_impulse, relative_velocity, push_gap and normal_mass
  /// back to `cs` (the constraints given to build), what apply_restitution reads.
  void unpack(std::vector<ContactConstraint>& cs) const;
  int group_count() const { return static_cast<int>(groups_.size()); }
  /// Threads for the work on the groups (none: the calling thread alone). With a team
  /// of two or more, build's regions (two or more) and enough groups for each thread
  /// (kParallelMinGroups in contact_solver_wide.cpp), warm_start and solve run the
  /// regions at once, thread t taking regions t, t + size, ..., and then the boundary
  /// on thread 0 (backward passes: the boundary first). The regions share no moving
  /// body, so they commute exactly (each group writes only its own moving bodies'
  /// rows), and the result is bit for bit the one without a team, for any number of
  /// threads. The work on each group alone (build's effective masses, set_motion,
  /// unpack) is split into contiguous parts, one per thread.
  void set_team(ParallelTeam* team) { team_ = team; }
  /// Regions (build's `starts`): region r is the groups [region_start(r),
  /// region_start(r + 1)), the last of region_count() + 1 the boundary's.
  int region_count() const { return static_cast<int>(region_start_.size()) - 2; }
  int region_start(int r) const { return region_start_[static_cast<std::size_t>(r)]; }

  /// One group: lane l holds constraint source_[kLanes g + l]. Every quantity is an
  /// array over the lanes; vectors are stored per component ([3][kLanes]).
  struct Group {
    std::array<int, kLanes> body_a{}, body_b{};  ///< state indices (`dummy` for padding)
    std::array<int, kLanes> row_a{}, row_b{};    ///< the bodies' rows in the solver's body array
    int points = 0;           ///< largest point count among the lanes
    bool friction = false;    ///< some lane has friction
    bool stiffened = false;   ///< some point has stiffening > 1 (SolverSettings::max_sag)
    /// Where lane l's velocities of A (B) are written back: its body's row if the body
    /// moves, else a sink row of the group's region that nothing reads. A static or
    /// kinematic body's row, which groups running at once may share, is only read, and
    /// the write stays unconditional (a branch per lane cost the pyramid's passes a
    /// fifth of their time).
    std::array<int, kLanes> write_a{}, write_b{};
    alignas(32) float inv_mass_a[kLanes] = {}, inv_mass_b[kLanes] = {};
    /// World inverse inertia (at the step's start, or as refresh_inertia last set it),
    /// symmetric: xx, yy, zz, xy, xz, yz.
    alignas(32) float ia[6][kLanes] = {}, ib[6][kLanes] = {};
    alignas(32) float n[3][kLanes] = {}, t1[3][kLanes] = {}, t2[3][kLanes] = {};
    alignas(32) float mu[kLanes] = {};
    /// ContactConstraint::allow (m; 0 for a padding lane, which pushes nothing).
    alignas(32) float allow[kLanes] = {};
    /// 1 where the lane's constraint has a body that does not move (ContactSoftness::fixed).
    alignas(32) float fixed[kLanes] = {};
    /// The lane's point count (0 for a padding lane): points past it are padding.
    alignas(32) float count[kLanes] = {};
    /// At the motion of the last set_motion, for the centroid row (solve), with rc_a,
    /// rc_b the means of the points' current anchors (m, world frame, from the centres
    /// of mass): rc_a x n and rc_b x n (m), and count^2 times the inverse effective
    /// mass along n at the anchors (1/kg), the sum of the rows' couplings K_ij.
    alignas(32) float cn_a[3][kLanes] = {}, cn_b[3][kLanes] = {};
    alignas(32) float coupling[kLanes] = {};
    /// ContactConstraintPoint::stiffening of the lane's points (one per constraint) and
    /// its inverse.
    alignas(32) float stiffening[kLanes] = {}, inv_stiffening[kLanes] = {};
    struct Point {
      alignas(32) float ra[3][kLanes] = {}, rb[3][kLanes] = {};
      /// ContactConstraintPoint::ca_n / cb_n.
      alignas(32) float ca_n[kLanes] = {}, cb_n[kLanes] = {};
      /// Separation at the step's start (m): adjusted_separation + n.(rb - ra).
      alignas(32) float base_separation[kLanes] = {}, normal_mass[kLanes] = {};
      alignas(32) float tangent_mass[2][kLanes] = {};
      alignas(32) float normal_impulse[kLanes] = {}, tangent_impulse[2][kLanes] = {};
      alignas(32) float max_normal_impulse[kLanes] = {}, relative_velocity[kLanes] = {};
      alignas(32) float push_gap[kLanes] = {};
      /// At the motion of the last set_motion: the anchors (m, world frame, from the
      /// centres of mass), the separation (m) and the normal row's effective mass.
      alignas(32) float ra_now[3][kLanes] = {}, rb_now[3][kLanes] = {};
      alignas(32) float separation[kLanes] = {}, mass_now[kLanes] = {};
    };
    std::array<Point, 4> p{};
  };
  const std::vector<Group>& groups() const { return groups_; }

  /// A body as the passes see it: its velocities (m/s, rad/s, world frame). Row 0 is
  /// the padding lanes' body (at rest, never written back).
  struct alignas(32) Row {
    float v[3], w[3], pad[2];
  };
  static_assert(sizeof(Row) == 32, "the passes move a row as one 8-float register");
  /// A body's motion since the step began, as set_motion reads it: dp (m), dq as x, y,
  /// z, w, and turn2 = |dq.xyz|^2, sin^2 of half the angle it turned.
  struct alignas(32) MotionRow {
    float dp[3], dq[4], turn2;
  };
  static_assert(sizeof(MotionRow) == 32, "set_motion moves a row as one 8-float register");

 private:
  void load(const std::vector<BodyState>& states);
  void store(std::vector<BodyState>& states) const;

  std::vector<Group> groups_;
  bool centroid_rows_ = true;    ///< build's centroid_rows
  std::vector<int> source_;      ///< per group and lane: index into cs, or -1 for padding
  std::vector<Row> rows_;        ///< the solver's bodies
  std::vector<MotionRow> motion_;  ///< their motion, per row (set_motion)
  std::vector<Row> loaded_;      ///< rows_ as load() wrote them (for the velocity changes)
  std::vector<int> row_state_;   ///< per row: its state index (row 0: dummy)
  std::vector<int> row_moves_;   ///< per row: 1 if its body moves (receives velocity changes)
  std::vector<std::uint8_t> refresh_;  ///< per row: scratch of refresh_inertia
  std::vector<int> row_of_;      ///< per state: its row, -1 if none (build's scratch)
  /// Runs f(begin, end) over the groups as the passes visit them (see set_team):
  /// on the team region by region, else in one call over all of them.
  template <class F>
  void run_groups(bool reverse, F&& f);
  /// Runs f(begin, end) over contiguous parts of the groups, one per thread, for work
  /// on each group alone (no order between groups).
  template <class F>
  void for_groups(F&& f) const;
  void unpack_groups(std::vector<ContactConstraint>& cs, int begin, int end) const;
  ParallelTeam* team_ = nullptr;
  std::vector<int> region_start_;  ///< see region_count
  // build's scratch: per position in the order, placed in a group yet; per state, the
  // last group it joined and the last group that passed over a constraint of it.
  std::vector<std::uint8_t> placed_;
  std::vector<int> in_group_, passed_over_;
};

}  // namespace wmo
