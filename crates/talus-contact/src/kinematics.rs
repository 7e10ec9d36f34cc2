//! Contact kinematics: geometry and relative motion of a pair, computed from the snapshot.

use glam::DVec3;
use talus_core::lanes::{F4, V4};
use talus_core::periodic::ImageLanes;
use talus_core::snapshot::{GrainReader, GrainSnapshot, WallState};

/// Everything a contact law needs to know about the pair at this instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactKinematics {
    /// Unit normal from `b` to `a`.
    pub normal: DVec3,
    /// Overlap δ (positive in contact), m.
    pub overlap: f64,
    /// Contact point (the middle of the overlap), the centre of `a` plus `branch_a`: the
    /// point [`crate::ContactGeometry::point`] derives after the evaluation.
    pub point: DVec3,
    /// Contact point minus the centre of `a`.
    pub branch_a: DVec3,
    /// Contact point minus the centre of `b` (zero for walls).
    pub branch_b: DVec3,
    /// Velocity of `a`'s material point at the contact minus `b`'s.
    pub relative_velocity: DVec3,
    /// Normal relative velocity, v·n: positive while separating.
    pub normal_velocity: f64,
    /// Tangential relative velocity at the contact point.
    pub tangential_velocity: DVec3,
    /// Relative displacement of the contact point over the step just taken, m: the
    /// half-step velocities times dt, with each grain's spin acting on the mean of its
    /// branch vector before and after the step. This is the displacement on which the
    /// integrator's trapezoidal rule makes the old and the new force work, so laws that
    /// accumulate springs or dashpot work over it keep the energy balance second order.
    pub displacement: DVec3,
    /// Overlap at the previous evaluation of this contact, m: zero for a new contact,
    /// negative once the bodies have parted. Set by [`Self::set_displacement`].
    pub previous_overlap: f64,
    /// Unit normal at the previous evaluation of this contact: zero for a new contact.
    /// Set by [`Self::set_displacement`].
    pub previous_normal: DVec3,
    /// ω_a − ω_b (ω_a for walls).
    pub relative_omega: DVec3,
    /// Reduced mass m_a m_b / (m_a + m_b) (walls: m_a), kg.
    pub effective_mass: f64,
    /// Reduced radius R_a R_b / (R_a + R_b) (walls: R_a), m.
    pub effective_radius: f64,
    /// Smaller radius of the pair, m.
    pub min_radius: f64,
}

impl ContactKinematics {
    /// Fills [`Self::displacement`] for a step `dt`, given the normal and overlap of the
    /// previous evaluation (`previous_normal` zero for a new contact) and the spins.
    /// Returns how much further the contact point moved with the old branch vectors
    /// than with the new ones over the step (zero for a new contact), m.
    #[inline]
    pub fn set_displacement(
        &mut self,
        previous_normal: DVec3,
        previous_overlap: f64,
        omega_a: DVec3,
        omega_b: DVec3,
        dt: f64,
    ) -> DVec3 {
        self.previous_overlap = previous_overlap;
        self.previous_normal = previous_normal;
        if previous_normal == DVec3::ZERO {
            self.displacement = self.relative_velocity * dt;
            return DVec3::ZERO;
        }
        // Branch vectors are −n (R_a − δ/2) and n (R_b − δ/2): each lies along the normal,
        // so its length is its projection on it (two square roots a contact less: about
        // 1 ns a grain-step, 4 % of the force loop, at the chute's 32,000 grains).
        let shift = 0.5 * (self.overlap - previous_overlap);
        let old_a = -previous_normal * (-self.branch_a.dot(self.normal) + shift);
        let old_b = if self.branch_b == DVec3::ZERO {
            DVec3::ZERO
        } else {
            previous_normal * (self.branch_b.dot(self.normal) + shift)
        };
        let correction = omega_a.cross(0.5 * (old_a - self.branch_a))
            - omega_b.cross(0.5 * (old_b - self.branch_b));
        self.displacement = (self.relative_velocity + correction) * dt;
        2.0 * correction * dt
    }

    /// Kinematics of grains `i` (a) and `j` (b) of the snapshot.
    #[inline]
    pub fn grain_grain(s: &GrainSnapshot, i: usize, j: usize) -> Self {
        let (ra, rb) = (s.radius(i), s.radius(j));
        // Across a Lees–Edwards seam b's nearest image moves faster than b itself.
        let (d, image_velocity) = s.separation_and_image_velocity(s.position(i), s.position(j));
        let dist = d.length();
        let normal = if dist > 0.0 {
            d * (1.0 / dist)
        } else {
            DVec3::Z
        };
        let overlap = ra + rb - dist;
        let branch_a = -normal * (ra - 0.5 * overlap);
        let branch_b = normal * (rb - 0.5 * overlap);
        let point = s.position(i) + branch_a;
        let (wa, wb) = (s.omega[i], s.omega[j]);
        let relative_velocity = (s.velocity(i) + wa.cross(branch_a))
            - (s.velocity(j) + image_velocity + wb.cross(branch_b));
        let normal_velocity = relative_velocity.dot(normal);
        let (inverse_ma, inverse_mb) = (s.inverse_mass(i), s.inverse_mass(j));
        Self {
            normal,
            overlap,
            point,
            branch_a,
            branch_b,
            relative_velocity,
            normal_velocity,
            tangential_velocity: relative_velocity - normal * normal_velocity,
            displacement: DVec3::ZERO,
            previous_overlap: 0.0,
            previous_normal: DVec3::ZERO,
            relative_omega: wa - wb,
            // A harmonic sum, so that a frozen partner (zero inverse mass) gives m_a.
            effective_mass: 1.0 / (inverse_ma + inverse_mb),
            effective_radius: ra * rb / (ra + rb),
            min_radius: ra.min(rb),
        }
    }

    /// Kinematics of grain `i` (a) against a wall (b).
    #[inline]
    pub fn grain_wall(s: &GrainSnapshot, i: usize, wall: &WallState) -> Self {
        let ra = s.radius(i);
        let normal = wall.normal;
        let distance = (s.position(i) - wall.point).dot(normal);
        let overlap = ra - distance;
        let branch_a = -normal * (ra - 0.5 * overlap);
        let point = s.position(i) + branch_a;
        let wa = s.omega[i];
        let relative_velocity = s.velocity(i) + wa.cross(branch_a) - wall.velocity;
        let normal_velocity = relative_velocity.dot(normal);
        Self {
            normal,
            overlap,
            point,
            branch_a,
            branch_b: DVec3::ZERO,
            relative_velocity,
            normal_velocity,
            tangential_velocity: relative_velocity - normal * normal_velocity,
            displacement: DVec3::ZERO,
            previous_overlap: 0.0,
            previous_normal: DVec3::ZERO,
            relative_omega: wa,
            effective_mass: 1.0 / s.inverse_mass(i),
            effective_radius: ra,
            min_radius: ra,
        }
    }
}

/// [`ContactKinematics`] of four grain–grain contacts at once, one per lane, computed
/// with the same operations in the same order as [`ContactKinematics::grain_grain`] and
/// [`ContactKinematics::set_displacement`]: every lane has the bits of the scalar form.
/// The lane forms of the laws ([`crate::ContactLaw::evaluate_lanes`]) read it.
#[derive(Clone, Copy, Debug)]
pub struct ContactKinematicsLanes {
    /// Unit normal from `b` to `a`.
    pub normal: V4,
    /// Overlap δ, m.
    pub overlap: F4,
    /// Contact point, the centre of `a` plus `branch_a`.
    pub point: V4,
    /// Contact point minus the centre of `a`.
    pub branch_a: V4,
    /// Contact point minus the centre of `b`.
    pub branch_b: V4,
    /// Velocity of `a`'s material point at the contact minus `b`'s.
    pub relative_velocity: V4,
    /// Normal relative velocity, positive while separating.
    pub normal_velocity: F4,
    /// Tangential relative velocity at the contact point.
    pub tangential_velocity: V4,
    /// Relative displacement of the contact point over the step just taken, m
    /// ([`ContactKinematics::displacement`]).
    pub displacement: V4,
    /// Overlap at the previous evaluation, m.
    pub previous_overlap: F4,
    /// Unit normal at the previous evaluation (zero for a new contact).
    pub previous_normal: V4,
    /// ω_a − ω_b.
    pub relative_omega: V4,
    /// Reduced mass, kg.
    pub effective_mass: F4,
    /// Reduced radius, m.
    pub effective_radius: F4,
    /// Smaller radius of the pair, m.
    pub min_radius: F4,
}

/// The spins of the two grains of four contacts, read with their kinematics.
#[derive(Clone, Copy, Debug)]
pub struct SpinLanes {
    /// Angular velocity of each contact's grain `a`.
    pub a: V4,
    /// Angular velocity of each contact's grain `b`.
    pub b: V4,
}

impl ContactKinematicsLanes {
    /// Kinematics of grains `i[k]` (a) and `j[k]` (b) of the snapshot (read through `s`,
    /// [`GrainSnapshot::reader`]) in lane `k`
    /// ([`ContactKinematics::grain_grain`]), in a box that is not sheared, whose
    /// nearest-image rule is `image` ([`GrainSnapshot::image_lanes`]). The
    /// displacement is left at zero until [`Self::set_displacement`].
    #[inline(always)]
    pub fn grain_grain(
        s: &GrainReader,
        image: &ImageLanes,
        i: [usize; 4],
        j: [usize; 4],
    ) -> (Self, SpinLanes) {
        let (a, b) = (s.gather4(i), s.gather4(j));
        let (ra, rb) = (a.radius, b.radius);
        let pb = b.position;
        let d = image.apply(a.position - pb);
        let dist = d.length();
        let zero = F4::zero();
        let normal = dist
            .gt(zero)
            .select3(d * (F4::splat(1.0) / dist), V4::splat(DVec3::Z));
        let overlap = ra + rb - dist;
        let half = F4::splat(0.5);
        let branch_a = -normal * (ra - half * overlap);
        let branch_b = normal * (rb - half * overlap);
        let point = a.position + branch_a;
        let (wa, wb) = (a.omega, b.omega);
        let (va, vb) = (a.velocity, b.velocity);
        // The scalar form adds the (here zero) velocity of b's image: kept, so that the
        // sign of a zero comes out the same.
        let relative_velocity = (va + wa.cross(branch_a)) - (vb + V4::zero() + wb.cross(branch_b));
        let normal_velocity = relative_velocity.dot(normal);
        let (inverse_ma, inverse_mb) = (a.inverse_mass, b.inverse_mass);
        let kin = Self {
            normal,
            overlap,
            point,
            branch_a,
            branch_b,
            relative_velocity,
            normal_velocity,
            tangential_velocity: relative_velocity - normal * normal_velocity,
            displacement: V4::zero(),
            previous_overlap: zero,
            previous_normal: V4::zero(),
            relative_omega: wa - wb,
            effective_mass: F4::splat(1.0) / (inverse_ma + inverse_mb),
            effective_radius: ra * rb / (ra + rb),
            // f64::min of two radii (neither is NaN).
            min_radius: rb.lt(ra).select(rb, ra),
        };
        (kin, SpinLanes { a: wa, b: wb })
    }

    /// [`ContactKinematics::set_displacement`] in four lanes: fills the displacement and
    /// the previous normal and overlap, and returns how much further the contact point
    /// moved with the old branch vectors than with the new ones.
    #[inline(always)]
    pub fn set_displacement(
        &mut self,
        previous_normal: V4,
        previous_overlap: F4,
        spin: SpinLanes,
        dt: f64,
    ) -> V4 {
        self.previous_overlap = previous_overlap;
        self.previous_normal = previous_normal;
        let dt = F4::splat(dt);
        let new = previous_normal.eq(V4::zero());
        let half = F4::splat(0.5);
        let shift = half * (self.overlap - previous_overlap);
        // Branch lengths as projections on the normal, as the scalar form takes them.
        let old_a = -previous_normal * (-self.branch_a.dot(self.normal) + shift);
        let old_b = self.branch_b.eq(V4::zero()).select3(
            V4::zero(),
            previous_normal * (self.branch_b.dot(self.normal) + shift),
        );
        let correction = spin.a.cross((old_a - self.branch_a) * half)
            - spin.b.cross((old_b - self.branch_b) * half);
        self.displacement = new.select3(
            self.relative_velocity * dt,
            (self.relative_velocity + correction) * dt,
        );
        new.select3(V4::zero(), (correction * F4::splat(2.0)) * dt)
    }
}

impl ContactKinematicsLanes {
    /// Four scalar kinematics side by side, lane `k` from `kin[k]`: for testing a law's
    /// lane form against its scalar form on the same contacts.
    pub fn from_scalar(kin: [ContactKinematics; 4]) -> Self {
        let v = |f: fn(&ContactKinematics) -> DVec3| V4::from_fn(|k| f(&kin[k]));
        let s = |f: fn(&ContactKinematics) -> f64| F4::from_fn(|k| f(&kin[k]));
        Self {
            normal: v(|k| k.normal),
            overlap: s(|k| k.overlap),
            point: v(|k| k.point),
            branch_a: v(|k| k.branch_a),
            branch_b: v(|k| k.branch_b),
            relative_velocity: v(|k| k.relative_velocity),
            normal_velocity: s(|k| k.normal_velocity),
            tangential_velocity: v(|k| k.tangential_velocity),
            displacement: v(|k| k.displacement),
            previous_overlap: s(|k| k.previous_overlap),
            previous_normal: v(|k| k.previous_normal),
            relative_omega: v(|k| k.relative_omega),
            effective_mass: s(|k| k.effective_mass),
            effective_radius: s(|k| k.effective_radius),
            min_radius: s(|k| k.min_radius),
        }
    }
}
