//! Periodic boundaries: a box whose opposite faces are identified along chosen axes.
//! Positions are wrapped into the box after each drift; pair separations take the
//! nearest image. (Lees–Edwards shear would add an image velocity and offset here.)

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::{Grain, Position};

/// The periodic box: `[lo, hi)` along each axis flagged in `axes`.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct PeriodicBox {
    /// Lower corner, m.
    pub lo: DVec3,
    /// Upper corner, m.
    pub hi: DVec3,
    /// Which axes are periodic.
    pub axes: [bool; 3],
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
    pub fn min_image(&self, mut d: DVec3) -> DVec3 {
        let l = self.length();
        for a in 0..3 {
            // Compare and shift instead of d − L·round(d/L): `round` is a libm call on
            // baseline x86-64 and this runs for every candidate pair.
            if self.axes[a] {
                if d[a] > 0.5 * l[a] {
                    d[a] -= l[a];
                } else if d[a] < -0.5 * l[a] {
                    d[a] += l[a];
                }
            }
        }
        d
    }

    /// The image of a position inside the box along the periodic axes.
    #[inline]
    pub fn wrap(&self, mut p: DVec3) -> DVec3 {
        let l = self.length();
        for a in 0..3 {
            if self.axes[a] {
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
}

/// Wraps grain positions back into the periodic box after the drift.
pub fn wrap_positions(periodic: Res<PeriodicBox>, mut grains: Query<&mut Position, With<Grain>>) {
    let b = *periodic;
    for mut p in grains.contiguous_iter_mut().expect("grain query is dense") {
        for p in p.bypass_change_detection().iter_mut() {
            p.0 = b.wrap(p.0);
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
        };
        let d = b.min_image(DVec3::new(0.9, 1.5, 4.0));
        assert!((d - DVec3::new(-0.1, -0.5, 4.0)).length() < 1e-15, "{d:?}");
        let w = b.wrap(DVec3::new(-0.25, 1.5, 7.0));
        assert!((w - DVec3::new(0.75, -0.5, 7.0)).length() < 1e-15);
        let w = b.wrap(DVec3::new(1.0, 1.0, 0.0));
        assert_eq!(w, DVec3::new(0.0, -1.0, 0.0));
        let tiny = b.wrap(DVec3::new(-1e-18, 0.0, 0.0));
        assert!(tiny.x >= 0.0 && tiny.x < 1.0);
    }
}
