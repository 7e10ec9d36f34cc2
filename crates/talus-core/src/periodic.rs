//! Periodic boundaries: a box whose opposite faces are identified along chosen axes.
//! Positions are wrapped into the box after each drift; pair separations take the
//! nearest image. With Lees–Edwards shear ([`LeesEdwards`]) the images across the
//! gradient seam are offset along the flow axis by Δ(t) = γ̇ L_g t and move at ±γ̇ L_g
//! (`docs/physics/lees-edwards.md`).

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::{Frozen, Grain, Position, Velocity};
use crate::resources::Clock;

/// Lees–Edwards (sliding-brick) shear of a periodic box: the periodic images one box
/// length up the gradient axis are displaced by `offset` along the flow axis and move at
/// `rate · L_g` along it, so that the mean flow is simple shear v_f = γ̇ (x_g − c_g) with
/// c_g the middle of the box along the gradient axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeesEdwards {
    /// Shear rate γ̇ = ∂v_f/∂x_g, 1/s.
    pub rate: f64,
    /// Flow axis f (0, 1, 2 for x, y, z).
    pub flow: usize,
    /// Gradient axis g (≠ f).
    pub gradient: usize,
    /// Current image offset Δ along the flow axis, reduced to [−L_f/2, L_f/2), m.
    pub offset: f64,
}

/// The periodic box: `[lo, hi)` along each axis flagged in `axes`.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct PeriodicBox {
    /// Lower corner, m.
    pub lo: DVec3,
    /// Upper corner, m.
    pub hi: DVec3,
    /// Which axes are periodic.
    pub axes: [bool; 3],
    /// Lees–Edwards shear, when the scene imposes one (both its axes periodic).
    pub shear: Option<LeesEdwards>,
}

impl PeriodicBox {
    /// Box lengths, m.
    #[inline]
    pub fn length(&self) -> DVec3 {
        self.hi - self.lo
    }

    /// The nearest image of a separation vector between two wrapped positions (each
    /// component within one box length, as between any two grains of the box).
    #[inline]
    pub fn min_image(&self, d: DVec3) -> DVec3 {
        self.min_image_with_velocity(d).0
    }

    /// The nearest image of a separation d = a − b between two wrapped positions, and
    /// the velocity that image of b has beyond b's own: zero except across a
    /// Lees–Edwards gradient seam, where it is ±γ̇ L_g along the flow axis. The relative
    /// velocity of the pair is v_a − v_b − (that velocity).
    #[inline]
    pub fn min_image_with_velocity(&self, mut d: DVec3) -> (DVec3, DVec3) {
        let l = self.length();
        let mut image_velocity = DVec3::ZERO;
        if let Some(shear) = &self.shear {
            // The gradient axis first: crossing its seam shifts the flow component, which
            // the flow axis's own nearest-image step below then brings back into range.
            let (g, f) = (shear.gradient, shear.flow);
            if d[g] > 0.5 * l[g] {
                // b's nearest image is one box up: at b + L_g e_g + Δ e_f.
                d[g] -= l[g];
                d[f] -= shear.offset;
                image_velocity[f] = shear.rate * l[g];
            } else if d[g] < -0.5 * l[g] {
                d[g] += l[g];
                d[f] += shear.offset;
                image_velocity[f] = -shear.rate * l[g];
            }
        }
        (self.axis_rule().apply(d), image_velocity)
    }

    /// The nearest-image rule of an unsheared box with its lengths precomputed, for the
    /// hot loops (`None` for a sheared box, whose seam needs [`Self::min_image_with_velocity`]).
    pub fn nearest_image(&self) -> Option<NearestImage> {
        self.shear.is_none().then(|| self.axis_rule())
    }

    /// The nearest image along each periodic axis on its own (no seam offset).
    #[inline]
    fn axis_rule(&self) -> NearestImage {
        let l = self.length();
        let axis = |a: usize| {
            if self.axes[a] {
                (l[a], 0.5 * l[a])
            } else {
                (0.0, f64::INFINITY)
            }
        };
        let [(lx, hx), (ly, hy), (lz, hz)] = [0, 1, 2].map(axis);
        NearestImage {
            length: DVec3::new(lx, ly, lz),
            half: DVec3::new(hx, hy, hz),
        }
    }

    /// The image of a position inside the box along the periodic axes.
    #[inline]
    pub fn wrap(&self, mut p: DVec3) -> DVec3 {
        let l = self.length();
        for a in 0..3 {
            // Most grains are inside the box: they stay exactly where they are.
            if self.axes[a] && !(p[a] >= self.lo[a] && p[a] < self.hi[a]) {
                let mut x = p[a] - self.lo[a];
                x -= l[a] * (x / l[a]).floor();
                // Rounding can land exactly on the upper face; that point is the lower one.
                if x >= l[a] {
                    x -= l[a];
                }
                p[a] = self.lo[a] + x;
            }
        }
        p
    }

    /// Brings a grain back into a sheared box: through the gradient seam the position is
    /// shifted by ∓Δ along the flow axis and the velocity by ∓γ̇ L_g (the grain becomes
    /// its own image), then every periodic axis is wrapped. The peculiar velocity
    /// v − γ̇ (x_g − c_g) e_f is unchanged.
    #[inline]
    pub fn wrap_sheared(&self, shear: &LeesEdwards, p: &mut DVec3, v: &mut DVec3) {
        let (g, f) = (shear.gradient, shear.flow);
        let lg = self.hi[g] - self.lo[g];
        // A grain moves far less than a box length per step: one crossing at most, but
        // loop so that a wild state is still wrapped consistently.
        while p[g] >= self.hi[g] {
            p[g] -= lg;
            p[f] -= shear.offset;
            v[f] -= shear.rate * lg;
        }
        while p[g] < self.lo[g] {
            p[g] += lg;
            p[f] += shear.offset;
            v[f] += shear.rate * lg;
        }
        *p = self.wrap(*p);
    }

    /// The streaming (mean shear) velocity at a position: γ̇ (x_g − c_g) along the flow
    /// axis, with c_g the middle of the box; zero without shear.
    #[inline]
    pub fn streaming_velocity(&self, p: DVec3) -> DVec3 {
        let mut u = DVec3::ZERO;
        if let Some(shear) = &self.shear {
            let g = shear.gradient;
            u[shear.flow] = shear.rate * (p[g] - 0.5 * (self.lo[g] + self.hi[g]));
        }
        u
    }

    /// Sets the Lees–Edwards offset for simulated time `t`: Δ = γ̇ L_g t reduced to
    /// [−L_f/2, L_f/2). Computed from t rather than accumulated, so it carries no drift.
    pub fn set_shear_time(&mut self, t: f64) {
        let l = self.length();
        if let Some(shear) = &mut self.shear {
            let lf = l[shear.flow];
            let raw = shear.rate * l[shear.gradient] * t;
            let mut offset = raw - lf * (raw / lf).round();
            if offset >= 0.5 * lf {
                offset -= lf;
            }
            if offset < -0.5 * lf {
                offset += lf;
            }
            shear.offset = offset;
        }
    }
}

/// The nearest-image rule of an unsheared periodic box, with the box lengths and half
/// lengths precomputed and no branch per axis: what the hot loops apply to every
/// candidate pair ([`PeriodicBox::nearest_image`]). The default is no periodic axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearestImage {
    /// Box length along each periodic axis, 0 along the others, m.
    length: DVec3,
    /// Half the box length along each periodic axis, infinite along the others, m.
    half: DVec3,
}

impl Default for NearestImage {
    fn default() -> Self {
        Self {
            length: DVec3::ZERO,
            half: DVec3::INFINITY,
        }
    }
}

impl NearestImage {
    /// The nearest image of a separation between two wrapped positions: the same as
    /// [`PeriodicBox::min_image`], bit for bit (one box length subtracted where a
    /// component exceeds half the box, added where it is below minus half).
    #[inline(always)]
    pub fn apply(&self, d: DVec3) -> DVec3 {
        let down = DVec3::select(d.cmplt(-self.half), -self.length, DVec3::ZERO);
        d - DVec3::select(d.cmpgt(self.half), self.length, down)
    }

    /// The rule in four lanes ([`ImageLanes`]).
    #[inline(always)]
    pub fn lanes(&self) -> ImageLanes {
        let splat = |v: DVec3| crate::lanes::V4::splat(v);
        ImageLanes {
            length: splat(self.length),
            half: splat(self.half),
            minus_length: splat(-self.length),
            minus_half: splat(-self.half),
        }
    }
}

/// [`NearestImage`] with its box lengths spread over four lanes, made once before a loop
/// that applies it to four separations at a time.
#[derive(Clone, Copy, Debug)]
pub struct ImageLanes {
    length: crate::lanes::V4,
    half: crate::lanes::V4,
    minus_length: crate::lanes::V4,
    minus_half: crate::lanes::V4,
}

impl ImageLanes {
    /// [`NearestImage::apply`] in four lanes, bit for bit.
    #[inline(always)]
    pub fn apply(&self, d: crate::lanes::V4) -> crate::lanes::V4 {
        use crate::lanes::F4;
        let axis = |x: F4, length: F4, half: F4, minus_length: F4, minus_half: F4| {
            let down = x.lt(minus_half).select(minus_length, F4::zero());
            x - x.gt(half).select(length, down)
        };
        let (l, h, ml, mh) = (self.length, self.half, self.minus_length, self.minus_half);
        crate::lanes::V4 {
            x: axis(d.x, l.x, h.x, ml.x, mh.x),
            y: axis(d.y, l.y, h.y, ml.y, mh.y),
            z: axis(d.z, l.z, h.z, ml.z, mh.z),
        }
    }
}

impl PeriodicBox {
    /// The unsheared wrap of one position as a closure with the box's bounds prepared:
    /// what [`crate::snapshot::gather_snapshot`] applies to each grain as it copies its
    /// position, so that the positions are read once a step instead of twice. (A
    /// Lees–Edwards box is wrapped by [`wrap_positions_sheared`], after which every grain
    /// is inside and this changes nothing.)
    #[inline]
    pub fn wrapper(&self) -> impl Fn(&mut DVec3) + Sync + '_ {
        let rule = self.wrap_rule();
        move |p: &mut DVec3| rule.apply(p)
    }

    /// The unsheared wrap with the box's bounds prepared ([`Self::wrapper`]), as a value
    /// whose test inlines into a loop over the grains.
    #[inline]
    pub fn wrap_rule(&self) -> WrapRule<'_> {
        // An axis that does not wrap has infinite bounds, so that almost every grain,
        // inside the box after a step, passes one test of all axes at once; the others
        // take the full rule.
        let bound = |a: usize, value: f64, open: f64| if self.axes[a] { value } else { open };
        WrapRule {
            lo: DVec3::from_array(std::array::from_fn(|a| {
                bound(a, self.lo[a], f64::NEG_INFINITY)
            })),
            hi: DVec3::from_array(std::array::from_fn(|a| bound(a, self.hi[a], f64::INFINITY))),
            box_: self,
        }
    }
}

/// The unsheared wrap of a [`PeriodicBox`] ([`PeriodicBox::wrap_rule`]).
#[derive(Clone, Copy, Debug)]
pub struct WrapRule<'a> {
    lo: DVec3,
    hi: DVec3,
    box_: &'a PeriodicBox,
}

impl WrapRule<'_> {
    /// Wraps one position into the box: one test of all axes for a grain inside it (almost
    /// every grain after a step), the box's full rule for the others.
    #[inline(always)]
    pub fn apply(&self, p: &mut DVec3) {
        let (lo, hi) = (self.lo, self.hi);
        let inside = (p.x >= lo.x)
            & (p.x < hi.x)
            & (p.y >= lo.y)
            & (p.y < hi.y)
            & (p.z >= lo.z)
            & (p.z < hi.z);
        if !inside {
            *p = self.box_.wrap(*p);
        }
    }
}

/// The wrap of a Lees–Edwards box, scheduled after the drift when the box is sheared (an
/// unsheared box is wrapped by [`crate::snapshot::gather_snapshot`] as it copies the
/// positions): advances the image offset to the pass's time, then wraps each grain,
/// moving position and velocity together through the gradient seam. Frozen grains are
/// wrapped in position only (their velocity is prescribed).
pub fn wrap_positions_sheared(
    clock: Res<Clock>,
    mut periodic: ResMut<PeriodicBox>,
    mut grains: Query<(&mut Position, &mut Velocity, Has<Frozen>), With<Grain>>,
) {
    periodic.set_shear_time(clock.time);
    let b = *periodic;
    let Some(shear) = b.shear else {
        return;
    };
    for (mut p, mut v, frozen) in &mut grains {
        let (p, v) = (
            &mut p.bypass_change_detection().0,
            &mut v.bypass_change_detection().0,
        );
        if frozen {
            let mut ignored = *v;
            b.wrap_sheared(&shear, p, &mut ignored);
        } else {
            b.wrap_sheared(&shear, p, v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_image_and_wrap() {
        let b = PeriodicBox {
            lo: DVec3::new(0.0, -1.0, 0.0),
            hi: DVec3::new(1.0, 1.0, 5.0),
            axes: [true, true, false],
            shear: None,
        };
        let d = b.min_image(DVec3::new(0.9, 1.5, 4.0));
        assert!((d - DVec3::new(-0.1, -0.5, 4.0)).length() < 1e-15, "{d:?}");
        let w = b.wrap(DVec3::new(-0.25, 1.5, 7.0));
        assert!((w - DVec3::new(0.75, -0.5, 7.0)).length() < 1e-15);
        let w = b.wrap(DVec3::new(1.0, 1.0, 0.0));
        assert_eq!(w, DVec3::new(0.0, -1.0, 0.0));
        let tiny = b.wrap(DVec3::new(-1e-18, 0.0, 0.0));
        assert!(tiny.x >= 0.0 && tiny.x < 1.0);
        // The precomputed rule shifts by one box length exactly where a component passes
        // half the box, and leaves the rest alone, bit for bit (signed zeros, NaN and
        // infinities included), against the rule written out axis by axis.
        let fast = b.nearest_image().expect("an unsheared box");
        let by_axis = |mut d: DVec3| {
            let l = b.hi - b.lo;
            for a in 0..3 {
                if b.axes[a] && d[a] > 0.5 * l[a] {
                    d[a] -= l[a];
                } else if b.axes[a] && d[a] < -0.5 * l[a] {
                    d[a] += l[a];
                }
            }
            d
        };
        let bits = |v: DVec3| v.to_array().map(f64::to_bits);
        for d in [
            DVec3::new(0.9, 1.5, 4.0),
            DVec3::new(-0.9, -1.5, -4.0),
            DVec3::new(0.5, 1.0, 0.0),
            DVec3::new(-0.5, -1.0, -0.0),
            DVec3::new(-0.0, -0.0, -0.0),
            DVec3::new(0.49, -0.99, 2.6),
            DVec3::new(f64::NAN, f64::INFINITY, f64::NEG_INFINITY),
            DVec3::new(f64::NEG_INFINITY, f64::NAN, f64::INFINITY),
        ] {
            assert_eq!(bits(fast.apply(d)), bits(by_axis(d)), "{d:?}");
            assert_eq!(bits(b.min_image(d)), bits(by_axis(d)), "{d:?}");
        }
        assert_eq!(
            NearestImage::default().apply(DVec3::new(7.0, -8.0, 9.0)),
            DVec3::new(7.0, -8.0, 9.0)
        );
    }

    /// The sliding-brick geometry: the image of b one box up sits at b + L_g e_g + Δ e_f
    /// and moves at γ̇ L_g; wrapping a grain through the seam lands it on its own image.
    #[test]
    fn sheared_images_and_wrap() {
        let mut b = PeriodicBox {
            lo: DVec3::ZERO,
            hi: DVec3::new(1.0, 2.0, 1.0),
            axes: [true, true, true],
            shear: Some(LeesEdwards {
                rate: 0.5,
                flow: 0,
                gradient: 1,
                offset: 0.0,
            }),
        };
        // Δ = γ̇ L_g t = 0.5 × 2 × 1.3 = 1.3 → 0.3 after reduction modulo L_f = 1.
        b.set_shear_time(1.3);
        let offset = b.shear.unwrap().offset;
        assert!((offset - 0.3).abs() < 1e-12, "{offset}");
        let a = DVec3::new(0.5, 1.95, 0.5);
        let below = DVec3::new(0.3, 0.05, 0.5);
        // Image of `below` one box up: (0.3 + 0.3, 2.05, 0.5) = (0.6, 2.05, 0.5).
        let (d, w) = b.min_image_with_velocity(a - below);
        assert!((d - DVec3::new(-0.1, -0.1, 0.0)).length() < 1e-12, "{d:?}");
        assert_eq!(w, DVec3::new(1.0, 0.0, 0.0));
        let (d, w) = b.min_image_with_velocity(below - a);
        assert!((d - DVec3::new(0.1, 0.1, 0.0)).length() < 1e-12, "{d:?}");
        assert_eq!(w, DVec3::new(-1.0, 0.0, 0.0));
        // Crossing the top seam: shifted back by Δ along x and slowed by γ̇ L_g = 1.
        let mut p = DVec3::new(0.2, 2.01, 0.5);
        let mut v = DVec3::new(0.9, 0.1, 0.0);
        let peculiar = v - b.streaming_velocity(p);
        b.wrap_sheared(&b.shear.unwrap(), &mut p, &mut v);
        assert!((p - DVec3::new(0.9, 0.01, 0.5)).length() < 1e-12, "{p:?}");
        assert!((v - DVec3::new(-0.1, 0.1, 0.0)).length() < 1e-12, "{v:?}");
        assert!((v - b.streaming_velocity(p) - peculiar).length() < 1e-12);
    }
}
