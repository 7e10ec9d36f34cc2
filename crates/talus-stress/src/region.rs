//! Sampling regions: the whole domain, axis-aligned boxes and slabs; the domain box
//! found from the walls and grains; and the clipping of branch segments to a region,
//! with its periodic images where the domain is periodic.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use talus_core::periodic::PeriodicBox;
use talus_core::snapshot::WallState;

/// How far from a unit axis vector a wall normal may be and still count as facing
/// along that axis when the domain box is found.
const AXIS_TOLERANCE: f64 = 1e-9;

/// The shape of a sampling region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RegionShape {
    /// Everything: all grains and all contacts, over the domain box.
    Domain,
    /// An axis-aligned box (in 2-D only x and y are used); its volume is its part of the
    /// domain box.
    Box {
        /// Lower corner, m.
        min: DVec3,
        /// Upper corner, m.
        max: DVec3,
    },
    /// The layer `min ≤ x[axis] < max`, unbounded along the other axes; its volume is
    /// its part of the domain box.
    Slab {
        /// 0, 1 or 2 for x, y, z.
        axis: usize,
        /// Lower bound along `axis`, m.
        min: f64,
        /// Upper bound along `axis`, m.
        max: f64,
    },
}

/// What kind of region a sample belongs to, as reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionKind {
    /// The whole domain.
    Domain,
    /// An axis-aligned box.
    Box,
    /// A slab.
    Slab,
}

impl RegionShape {
    /// The kind, for reports.
    pub fn kind(&self) -> RegionKind {
        match self {
            RegionShape::Domain => RegionKind::Domain,
            RegionShape::Box { .. } => RegionKind::Box,
            RegionShape::Slab { .. } => RegionKind::Slab,
        }
    }
}

/// A named sampling region.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionSpec {
    /// Name in reports and recording paths (`stress/<name>/...`).
    pub name: String,
    /// Where it is.
    pub shape: RegionShape,
    /// Imposed shear rate γ̇ for the inertial number, 1/s; `None`: estimated from the
    /// grain velocities when possible.
    pub shear_rate: Option<f64>,
}

/// An axis-aligned box, possibly unbounded along some axes (infinite bounds).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Lower corner (components may be −∞).
    pub min: DVec3,
    /// Upper corner (components may be +∞).
    pub max: DVec3,
}

impl Bounds {
    /// All of space.
    pub const EVERYWHERE: Bounds = Bounds {
        min: DVec3::NEG_INFINITY,
        max: DVec3::INFINITY,
    };

    /// Whether `p` lies inside, half-open: `min ≤ p < max` on every axis, so that regions
    /// tiling space claim each grain centre exactly once.
    #[inline]
    pub fn contains(&self, p: DVec3) -> bool {
        (0..3).all(|d| self.min[d] <= p[d] && p[d] < self.max[d])
    }

    /// Fraction of the segment from `a` to `b` that lies inside (Liang–Barsky clipping).
    /// A segment of zero length counts as its point.
    #[inline]
    pub fn segment_fraction(&self, a: DVec3, b: DVec3) -> f64 {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for d in 0..3 {
            let delta = b[d] - a[d];
            if delta == 0.0 {
                if !(self.min[d] <= a[d] && a[d] < self.max[d]) {
                    return 0.0;
                }
                continue;
            }
            // Entry and exit parameters along this axis (±∞ for unbounded sides).
            let ta = (self.min[d] - a[d]) / delta;
            let tb = (self.max[d] - a[d]) / delta;
            let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
            t0 = t0.max(lo);
            t1 = t1.min(hi);
            if t1 <= t0 {
                return 0.0;
            }
        }
        t1 - t0
    }

    /// The common part of two boxes (empty boxes have `max` below `min` somewhere).
    pub fn intersection(&self, other: &Bounds) -> Bounds {
        Bounds {
            min: self.min.max(other.min),
            max: self.max.min(other.max),
        }
    }

    /// Volume of the box over the first `dims` axes (in 2-D an area times the unit
    /// thickness of the disk mass model), m³; 0 when an extent is not positive or not
    /// finite.
    pub fn volume(&self, dims: usize) -> f64 {
        let mut v = 1.0;
        for d in 0..dims {
            let extent = self.max[d] - self.min[d];
            if !(extent.is_finite() && extent > 0.0) {
                return 0.0;
            }
            v *= extent;
        }
        v
    }
}

/// Image shifts, in box lengths, tried along a periodic axis around the image of a region
/// whose lower face is the last one at or below a segment's start: a segment reaching at
/// most one box length from its start meets no other (see
/// [`Bounds::periodic_segment_fraction`]).
const IMAGE_SHIFTS: [f64; 3] = [-1.0, 0.0, 1.0];

/// The periodic axes of a sample and their lengths: along them a region is repeated
/// every box length, so that it holds the grains and branch parts of its images too.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Seams {
    /// Which axes are periodic.
    pub axes: [bool; 3],
    /// Box length along each periodic axis, m (unused along the others).
    pub length: DVec3,
}

impl Seams {
    /// No periodic axis.
    pub const NONE: Seams = Seams {
        axes: [false; 3],
        length: DVec3::ZERO,
    };

    /// The seams of a periodic box, if there is one.
    pub fn of(periodic: Option<&PeriodicBox>) -> Seams {
        periodic.map_or(Seams::NONE, |b| Seams {
            axes: b.axes,
            length: b.length(),
        })
    }

    /// Whether a box bounded along `axis` from `min` to `max` is repeated along it: a
    /// periodic axis and a finite extent.
    fn repeats(&self, axis: usize, min: f64, max: f64) -> bool {
        self.axes[axis] && min.is_finite() && max.is_finite()
    }
}

impl Bounds {
    /// Whether `p` or one of its periodic images lies inside (half-open as
    /// [`Bounds::contains`]). Along a periodic axis the box must be narrower than the
    /// period (see [`region_boxes`], which makes wider ones unbounded there).
    pub fn contains_periodic(&self, p: DVec3, seams: &Seams) -> bool {
        (0..3).all(|d| {
            let (lo, hi) = (self.min[d], self.max[d]);
            if seams.repeats(d, lo, hi) {
                let l = seams.length[d];
                // The image of p at or above lo, within one period.
                let mut x = p[d] - l * ((p[d] - lo) / l).floor();
                if x < lo {
                    x += l;
                }
                x < hi
            } else {
                lo <= p[d] && p[d] < hi
            }
        })
    }

    /// Fraction of the segment from `a` to `b` inside the box or one of its periodic
    /// images. Along a periodic axis the box must be narrower than the period, so that
    /// its images are disjoint and their fractions add, and the segment must reach at
    /// most one period from `a` along it (a branch between nearest images reaches half
    /// a period at most). Without periodic axes this is [`Bounds::segment_fraction`].
    pub fn periodic_segment_fraction(&self, a: DVec3, b: DVec3, seams: &Seams) -> f64 {
        // Per axis, the parameter intervals t ∈ [0, 1] in which the segment lies inside
        // the slab of the box (and of its images) along that axis; the fraction is the
        // measure of the intersection over the axes of these disjoint unions.
        let mut spans = [[(0.0f64, 0.0f64); IMAGE_SHIFTS.len()]; 3];
        let mut counts = [0usize; 3];
        for d in 0..3 {
            let repeats = seams.repeats(d, self.min[d], self.max[d]);
            let shifts: &[f64] = if repeats {
                &IMAGE_SHIFTS
            } else {
                &IMAGE_SHIFTS[1..2]
            };
            // The image whose lower face is the last at or below a: the segment lies
            // between the faces of the images just below and just above it.
            let base = if repeats {
                ((a[d] - self.min[d]) / seams.length[d]).floor()
            } else {
                0.0
            };
            let delta = b[d] - a[d];
            for &k in shifts {
                let shift = (base + k) * seams.length[d];
                let (lo, hi) = (self.min[d] + shift, self.max[d] + shift);
                let span = if delta == 0.0 {
                    (lo <= a[d] && a[d] < hi).then_some((0.0, 1.0))
                } else {
                    let ta = (lo - a[d]) / delta;
                    let tb = (hi - a[d]) / delta;
                    let (t0, t1) = if ta <= tb { (ta, tb) } else { (tb, ta) };
                    let (t0, t1) = (t0.max(0.0), t1.min(1.0));
                    (t1 > t0).then_some((t0, t1))
                };
                if let Some(span) = span {
                    spans[d][counts[d]] = span;
                    counts[d] += 1;
                }
            }
            if counts[d] == 0 {
                return 0.0;
            }
        }
        let mut total = 0.0;
        for &(x0, x1) in &spans[0][..counts[0]] {
            for &(y0, y1) in &spans[1][..counts[1]] {
                for &(z0, z1) in &spans[2][..counts[2]] {
                    let t0 = x0.max(y0).max(z0);
                    let t1 = x1.min(y1).min(z1);
                    if t1 > t0 {
                        total += t1 - t0;
                    }
                }
            }
        }
        total
    }
}

/// Where the boxes of a sample come from: the walls and the grains' extent.
pub(crate) struct DomainInputs<'a> {
    /// Walls of the snapshot.
    pub walls: &'a [WallState],
    /// Lowest grain surface point along each axis (centre − radius).
    pub grain_min: DVec3,
    /// Highest grain surface point along each axis (centre + radius).
    pub grain_max: DVec3,
    /// 2 or 3.
    pub dims: usize,
}

/// The domain box: along each in-plane axis, each side is the innermost plane wall
/// facing along that axis (normal +e_d for the low side, −e_d for the high side) if
/// there is one, else the outermost grain surface. In 2-D the z extent is the unit
/// thickness [−0.5, 0.5] m of the disk mass model.
pub(crate) fn domain_bounds(inputs: &DomainInputs) -> Bounds {
    let mut min = inputs.grain_min;
    let mut max = inputs.grain_max;
    for d in 0..inputs.dims {
        let mut low_wall: Option<f64> = None;
        let mut high_wall: Option<f64> = None;
        for w in inputs.walls {
            let mut axis = DVec3::ZERO;
            axis[d] = 1.0;
            if (w.normal - axis).length() < AXIS_TOLERANCE {
                low_wall = Some(low_wall.map_or(w.point[d], |x| x.max(w.point[d])));
            } else if (w.normal + axis).length() < AXIS_TOLERANCE {
                high_wall = Some(high_wall.map_or(w.point[d], |x| x.min(w.point[d])));
            }
        }
        if let Some(x) = low_wall {
            min[d] = x;
        }
        if let Some(x) = high_wall {
            max[d] = x;
        }
    }
    if inputs.dims == 2 {
        min.z = -0.5;
        max.z = 0.5;
    }
    Bounds { min, max }
}

/// The domain box of a sample: [`domain_bounds`] from the walls and the grains' extent,
/// and along each periodic axis the periodic box itself.
pub(crate) fn sample_domain(inputs: &DomainInputs, periodic: Option<&PeriodicBox>) -> Bounds {
    let mut domain = domain_bounds(inputs);
    if let Some(b) = periodic {
        for a in 0..3 {
            if b.axes[a] {
                domain.min[a] = b.lo[a];
                domain.max[a] = b.hi[a];
            }
        }
    }
    domain
}

/// The boxes of one region for one sample: `clip` decides which grain centres belong to
/// it and how much of each branch segment counts; `volume` is the box whose volume
/// divides the sums (and is reported): the region's part of the domain box, so that a
/// region reaching past the walls (or past the grains, where no wall bounds the domain)
/// is not diluted by empty space. Along a periodic axis the region is repeated every
/// period (`seams`): it holds the grains and branch parts of its images, and its volume
/// there is its own extent (at most one period), wherever it lies relative to the box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RegionBoxes {
    /// Membership of grain centres and clipping of branch segments.
    pub clip: Bounds,
    /// The box whose volume divides the sums.
    pub volume: Bounds,
    /// Whether every contact counts whole (the domain: no clipping at all).
    pub whole: bool,
    /// The periodic axes along which `clip` is repeated.
    pub seams: Seams,
}

impl RegionBoxes {
    /// Whether a grain centre belongs to the region (or to one of its images).
    #[inline]
    pub fn holds(&self, p: DVec3) -> bool {
        self.whole || self.clip.contains_periodic(p, &self.seams)
    }

    /// The fraction of the branch segment from `a` to `b` that counts in the region: 1 for
    /// the domain, else the part inside the region and its periodic images.
    #[inline]
    pub fn fraction(&self, a: DVec3, b: DVec3) -> f64 {
        if self.whole {
            1.0
        } else {
            self.clip.periodic_segment_fraction(a, b, &self.seams)
        }
    }
}

/// The boxes of a region given the domain box and the periodic axes.
pub(crate) fn region_boxes(
    shape: &RegionShape,
    domain: &Bounds,
    dims: usize,
    seams: &Seams,
) -> RegionBoxes {
    let (mut clip, mut volume, whole) = match *shape {
        RegionShape::Domain => (Bounds::EVERYWHERE, *domain, true),
        RegionShape::Box { min, max } => {
            let mut clip = Bounds { min, max };
            let mut volume = clip.intersection(domain);
            if dims == 2 {
                // Disks all lie in z = 0; the z extent is the unit thickness.
                clip.min.z = f64::NEG_INFINITY;
                clip.max.z = f64::INFINITY;
                volume.min.z = -0.5;
                volume.max.z = 0.5;
            }
            (clip, volume, false)
        }
        RegionShape::Slab { axis, min, max } => {
            let mut clip = Bounds::EVERYWHERE;
            let mut volume = *domain;
            if axis < 3 {
                clip.min[axis] = min;
                clip.max[axis] = max;
                volume.min[axis] = volume.min[axis].max(min);
                volume.max[axis] = volume.max[axis].min(max);
            }
            (clip, volume, false)
        }
    };
    if !whole {
        for d in 0..3 {
            if !seams.repeats(d, clip.min[d], clip.max[d]) {
                continue;
            }
            if clip.max[d] - clip.min[d] >= seams.length[d] {
                // At least a whole period: every image of every point is inside.
                clip.min[d] = f64::NEG_INFINITY;
                clip.max[d] = f64::INFINITY;
                volume.min[d] = domain.min[d];
                volume.max[d] = domain.max[d];
            } else {
                // Its own extent, wherever it lies: its images fill the rest.
                volume.min[d] = clip.min[d];
                volume.max[d] = clip.max[d];
            }
        }
    }
    RegionBoxes {
        clip,
        volume,
        whole,
        seams: *seams,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy_ecs::entity::Entity;

    fn unit_box() -> Bounds {
        Bounds {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        }
    }

    #[test]
    fn segment_fraction_of_a_crossing_segment() {
        let b = unit_box();
        let f = b.segment_fraction(DVec3::new(0.5, 0.5, -1.0), DVec3::new(0.5, 0.5, 0.5));
        assert!((f - 0.5 / 1.5).abs() < 1e-15);
        assert_eq!(
            b.segment_fraction(DVec3::splat(0.2), DVec3::splat(0.7)),
            1.0
        );
        assert_eq!(
            b.segment_fraction(DVec3::new(2.0, 0.5, 0.5), DVec3::new(3.0, 0.5, 0.5)),
            0.0
        );
        // Diagonal through a corner region: x from −1 to 1 and y from 0.5 to 1.5 in
        // the same parameter; inside for x ≥ 0 and y < 1, i.e. t in [0.5, 0.5]: empty.
        let f = b.segment_fraction(DVec3::new(-1.0, 0.5, 0.5), DVec3::new(1.0, 1.5, 0.5));
        assert_eq!(f, 0.0);
    }

    #[test]
    fn slabs_tiling_space_share_a_segment_exactly() {
        let a = DVec3::new(0.1, 0.2, -0.3);
        let b = DVec3::new(0.4, -0.1, 0.9);
        let cuts = [-1.0, 0.0, 0.25, 0.5, 2.0];
        let total: f64 = cuts
            .windows(2)
            .map(|w| {
                let mut s = Bounds::EVERYWHERE;
                s.min.z = w[0];
                s.max.z = w[1];
                s.segment_fraction(a, b)
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-15);
    }

    #[test]
    fn periodic_images_of_a_region_hold_the_branch_across_the_seam() {
        let seams = Seams {
            axes: [true, false, false],
            length: DVec3::new(1.0, 0.0, 0.0),
        };
        let slab = |lo: f64, hi: f64| {
            let mut s = Bounds::EVERYWHERE;
            s.min.x = lo;
            s.max.x = hi;
            s
        };
        // A branch from 0.9 to 1.1 (its far end is the image of a grain at 0.1).
        let (a, b) = (DVec3::new(0.9, 0.3, 0.0), DVec3::new(1.1, 0.2, 0.0));
        let first = slab(0.0, 0.25).periodic_segment_fraction(a, b, &seams);
        assert!((first - 0.5).abs() < 1e-15, "{first}");
        // Without the images the part past the seam is lost.
        assert_eq!(slab(0.0, 0.25).segment_fraction(a, b), 0.0);
        // Slabs tiling the box share the branch exactly.
        let cuts = [0.0, 0.25, 0.5, 0.95, 1.0];
        let total: f64 = cuts
            .windows(2)
            .map(|w| slab(w[0], w[1]).periodic_segment_fraction(a, b, &seams))
            .sum();
        assert!((total - 1.0).abs() < 1e-15, "{total}");
        // A region across the seam, given on either side of it, holds the whole branch.
        for (lo, hi) in [(-0.2, 0.2), (0.8, 1.2), (1.8, 2.2), (-2.2, -1.8)] {
            let f = slab(lo, hi).periodic_segment_fraction(a, b, &seams);
            assert!((f - 1.0).abs() < 1e-15, "({lo}, {hi}): {f}");
            assert!(slab(lo, hi).contains_periodic(DVec3::new(0.05, 0.0, 0.0), &seams));
            assert!(slab(lo, hi).contains_periodic(DVec3::new(0.85, 0.0, 0.0), &seams));
            assert!(!slab(lo, hi).contains_periodic(DVec3::new(0.5, 0.0, 0.0), &seams));
        }
        // Along a non-periodic axis nothing is repeated.
        let mut lower = Bounds::EVERYWHERE;
        lower.max.y = 0.25;
        let f = lower.periodic_segment_fraction(a, b, &seams);
        assert!((f - 0.5).abs() < 1e-15, "{f}");
    }

    #[test]
    fn a_region_of_a_whole_period_is_unbounded_along_it() {
        let seams = Seams {
            axes: [false, false, true],
            length: DVec3::new(0.0, 0.0, 2.0),
        };
        let domain = Bounds {
            min: DVec3::ZERO,
            max: DVec3::new(1.0, 1.0, 2.0),
        };
        let wide = RegionShape::Slab {
            axis: 2,
            min: -1.0,
            max: 3.0,
        };
        let boxes = region_boxes(&wide, &domain, 3, &seams);
        assert_eq!(boxes.volume, domain);
        assert!(boxes.holds(DVec3::new(0.5, 0.5, 1.9)));
        let a = DVec3::new(0.5, 0.5, 1.9);
        assert_eq!(boxes.fraction(a, a + DVec3::new(0.0, 0.0, 0.3)), 1.0);
        let seam = RegionShape::Slab {
            axis: 2,
            min: -0.5,
            max: 0.5,
        };
        let boxes = region_boxes(&seam, &domain, 3, &seams);
        assert_eq!(boxes.volume.volume(3), 1.0);
        assert!(boxes.holds(DVec3::new(0.5, 0.5, 1.9)));
        assert!(!boxes.holds(DVec3::new(0.5, 0.5, 1.0)));
    }

    #[test]
    fn domain_box_from_walls_then_grains() {
        let wall = |p: DVec3, n: DVec3| WallState {
            entity: Entity::PLACEHOLDER,
            point: p,
            normal: n,
            velocity: DVec3::ZERO,
            material: 0,
        };
        // A floor and two x walls; no y walls and no lid.
        let walls = [
            wall(DVec3::ZERO, DVec3::Z),
            wall(DVec3::new(-1.0, 0.0, 0.0), DVec3::X),
            wall(DVec3::new(2.0, 0.0, 0.0), -DVec3::X),
            wall(DVec3::new(-0.5, 0.0, 0.0), DVec3::X),
        ];
        let b = domain_bounds(&DomainInputs {
            walls: &walls,
            grain_min: DVec3::new(-0.4, -3.0, 0.1),
            grain_max: DVec3::new(1.0, 3.0, 5.0),
            dims: 3,
        });
        assert_eq!(b.min, DVec3::new(-0.5, -3.0, 0.0));
        assert_eq!(b.max, DVec3::new(2.0, 3.0, 5.0));
        assert_eq!(b.volume(3), 2.5 * 6.0 * 5.0);
    }
}
