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
/// Under Lees–Edwards shear the images one period up the gradient axis are also shifted
/// by the offset Δ along the flow axis (sliding bricks): the image lattice is spanned by
/// L_g e_g + Δ e_f and the box lengths along the other axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Seams {
    /// Which axes are periodic.
    pub axes: [bool; 3],
    /// Box length along each periodic axis, m (unused along the others).
    pub length: DVec3,
    /// The sheared seam, when the box is sheared by Lees–Edwards boundaries.
    pub shear: Option<ShearedSeam>,
}

/// The Lees–Edwards seam of a sheared box, as the regions see it: the geometry of the
/// images at the instant of the sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShearedSeam {
    /// Flow axis f.
    pub flow: usize,
    /// Gradient axis g (≠ f).
    pub gradient: usize,
    /// Offset Δ of the image one period up the gradient axis, along the flow axis, m.
    pub offset: f64,
    /// Speed of that image along the flow axis beyond the original's, γ̇ L_g, m/s.
    pub image_speed: f64,
}

impl Seams {
    /// No periodic axis.
    pub const NONE: Seams = Seams {
        axes: [false; 3],
        length: DVec3::ZERO,
        shear: None,
    };

    /// The seams of a periodic box, if there is one, with its Lees–Edwards offset.
    pub fn of(periodic: Option<&PeriodicBox>) -> Seams {
        periodic.map_or(Seams::NONE, |b| Seams {
            axes: b.axes,
            length: b.length(),
            shear: b.shear.map(|s| ShearedSeam {
                flow: s.flow,
                gradient: s.gradient,
                offset: s.offset,
                image_speed: s.rate * b.length()[s.gradient],
            }),
        })
    }

    /// Whether a box bounded along `axis` from `min` to `max` is repeated along it: a
    /// periodic axis and a finite extent.
    fn repeats(&self, axis: usize, min: f64, max: f64) -> bool {
        self.axes[axis] && min.is_finite() && max.is_finite()
    }

    /// The sheared seam, where it matters to `b`: a box repeated along both the flow and
    /// the gradient axis. A box unbounded along the flow axis is its own image under any
    /// shift along it, and one unbounded along the gradient axis has no image across the
    /// seam ([`region_boxes`] bounds a flow-bounded region along the gradient axis).
    fn shear_for(&self, b: &Bounds) -> Option<ShearedSeam> {
        self.shear.filter(|s| {
            self.repeats(s.flow, b.min[s.flow], b.max[s.flow])
                && self.repeats(s.gradient, b.min[s.gradient], b.max[s.gradient])
        })
    }

    /// These seams without repetition along `axis`.
    fn without(&self, axis: usize) -> Seams {
        let mut plain = *self;
        plain.axes[axis] = false;
        plain.shear = None;
        plain
    }
}

impl Bounds {
    /// Whether `p` or one of its periodic images lies inside (half-open as
    /// [`Bounds::contains`]). Along a periodic axis the box must be narrower than the
    /// period (see [`region_boxes`], which makes wider ones unbounded there). Under
    /// Lees–Edwards shear the image k periods up the gradient axis is also shifted by k Δ
    /// along the flow axis.
    pub fn contains_periodic(&self, p: DVec3, seams: &Seams) -> bool {
        self.image_inside(p, seams).is_some()
    }

    /// The image of `p` that lies inside the box (see [`Bounds::contains_periodic`]), and
    /// how many periods k it was moved down the Lees–Edwards gradient axis (its flow
    /// coordinate moved by −k Δ; 0 without shear), or `None` when no image is inside.
    /// A grain held through such an image moves with its velocity less k γ̇ L_g e_f.
    pub fn image_inside(&self, p: DVec3, seams: &Seams) -> Option<(DVec3, f64)> {
        if let Some(shear) = seams.shear_for(self) {
            // The gradient axis first: the one image of p whose gradient coordinate is at
            // or above the box's lower face within a period fixes the brick, hence the
            // flow shift; the other axes then take their plain images.
            let (g, f) = (shear.gradient, shear.flow);
            let (lo, l) = (self.min[g], seams.length[g]);
            let mut periods = ((p[g] - lo) / l).floor();
            let mut x = p[g] - l * periods;
            if x < lo {
                x += l;
                periods -= 1.0;
            }
            if x >= self.max[g] {
                return None;
            }
            let mut image = p;
            image[g] = x;
            image[f] -= periods * shear.offset;
            return self
                .plain_image_inside(image, &seams.without(g))
                .map(|q| (q, periods));
        }
        self.plain_image_inside(p, seams).map(|q| (q, 0.0))
    }

    /// [`Bounds::image_inside`] with each axis's images independent of the others.
    fn plain_image_inside(&self, p: DVec3, seams: &Seams) -> Option<DVec3> {
        let mut image = p;
        for d in 0..3 {
            let (lo, hi) = (self.min[d], self.max[d]);
            if seams.repeats(d, lo, hi) {
                let l = seams.length[d];
                // The image of p at or above lo, within one period.
                let mut x = p[d] - l * ((p[d] - lo) / l).floor();
                if x < lo {
                    x += l;
                }
                if x >= hi {
                    return None;
                }
                image[d] = x;
            } else if !(lo <= p[d] && p[d] < hi) {
                return None;
            }
        }
        Some(image)
    }

    /// Fraction of the segment from `a` to `b` inside the box or one of its periodic
    /// images. Along a periodic axis the box must be narrower than the period, so that
    /// its images are disjoint and their fractions add, and the segment must reach at
    /// most one period from `a` along it (a branch between nearest images reaches half
    /// a period at most). Under Lees–Edwards shear the image k periods up the gradient
    /// axis is also shifted by k Δ along the flow axis. Without periodic axes this is
    /// [`Bounds::segment_fraction`].
    pub fn periodic_segment_fraction(&self, a: DVec3, b: DVec3, seams: &Seams) -> f64 {
        let Some(shear) = seams.shear_for(self) else {
            return self.plain_periodic_segment_fraction(a, b, seams);
        };
        // The segment meets only the bricks of the three gradient images around the one
        // whose lower face is the last at or below a (as along a plain periodic axis);
        // within each, the image is a plain box repeated along the other axes.
        let (g, f) = (shear.gradient, shear.flow);
        let l = seams.length[g];
        let base = ((a[g] - self.min[g]) / l).floor();
        let plain = seams.without(g);
        IMAGE_SHIFTS
            .iter()
            .map(|&k| {
                let periods = base + k;
                let mut image = *self;
                image.min[g] += periods * l;
                image.max[g] += periods * l;
                image.min[f] += periods * shear.offset;
                image.max[f] += periods * shear.offset;
                image.plain_periodic_segment_fraction(a, b, &plain)
            })
            .sum()
    }

    /// [`Bounds::periodic_segment_fraction`] with each axis's images independent of the
    /// others.
    fn plain_periodic_segment_fraction(&self, a: DVec3, b: DVec3, seams: &Seams) -> f64 {
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

/// The grains' extent (lowest and highest surface point along each axis) from their
/// centres and radii; zero when there is no grain or a position is not finite.
pub(crate) fn grain_extent(grains: impl Iterator<Item = (DVec3, f64)>) -> (DVec3, DVec3) {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for (p, r) in grains {
        lo = lo.min(p - DVec3::splat(r));
        hi = hi.max(p + DVec3::splat(r));
    }
    if lo.is_finite() && hi.is_finite() {
        (lo, hi)
    } else {
        (DVec3::ZERO, DVec3::ZERO)
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
/// Under Lees–Edwards shear the images across the gradient seam slide along the flow
/// axis with the offset Δ (see [`Seams`]).
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
    #[cfg(test)]
    pub fn holds(&self, p: DVec3) -> bool {
        self.held_image(p).is_some()
    }

    /// The image of a grain centre that belongs to the region, with the number of
    /// periods it was moved down a Lees–Edwards gradient axis ([`Bounds::image_inside`]);
    /// the centre itself for the domain; `None` when the grain is not in the region.
    #[inline]
    pub fn held_image(&self, p: DVec3) -> Option<(DVec3, f64)> {
        if self.whole {
            Some((p, 0.0))
        } else {
            self.clip.image_inside(p, &self.seams)
        }
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
        if let Some(shear) = seams.shear {
            let (f, g) = (shear.flow, shear.gradient);
            if seams.repeats(f, clip.min[f], clip.max[f]) && !clip.min[g].is_finite() {
                // Bounded along the flow but spanning the gradient period: under shear
                // its images across the seam slide along the flow, so it is the box's
                // own gradient period [lo_g, hi_g), repeated as sliding bricks (an
                // unbounded layer would meet each brick at a different flow range).
                clip.min[g] = domain.min[g];
                clip.max[g] = domain.max[g];
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
            shear: None,
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

    /// A box [0, 1) × [0, 2) periodic in x and y, sheared with flow x, gradient y, at an
    /// offset Δ = 0.3: the image one period up is at (x + 0.3, y + 2).
    fn sheared_seams() -> Seams {
        Seams {
            axes: [true, true, false],
            length: DVec3::new(1.0, 2.0, 0.0),
            shear: Some(ShearedSeam {
                flow: 0,
                gradient: 1,
                offset: 0.3,
                image_speed: 0.0,
            }),
        }
    }

    fn flat_box(x: (f64, f64), y: (f64, f64)) -> Bounds {
        Bounds {
            min: DVec3::new(x.0, y.0, f64::NEG_INFINITY),
            max: DVec3::new(x.1, y.1, f64::INFINITY),
        }
    }

    #[test]
    fn the_images_of_a_region_across_the_sheared_seam_slide_with_the_offset() {
        let seams = sheared_seams();
        // p's image one period up is (0.8, 2.1): a box there holds p, the box at the
        // same x without the shift does not.
        let p = DVec3::new(0.5, 0.1, 0.0);
        let above = flat_box((0.7, 0.9), (1.9, 2.2));
        assert!(above.contains_periodic(p, &seams));
        assert!(!flat_box((0.4, 0.6), (1.9, 2.2)).contains_periodic(p, &seams));
        // Plain periodic images would have it the other way round.
        let plain = Seams {
            shear: None,
            ..seams
        };
        assert!(!above.contains_periodic(p, &plain));
        // The same box given one brick down (−Δ along x, −2 along y), or one period
        // along x further, holds the same points.
        let below = flat_box((0.4, 0.6), (-0.1, 0.2));
        let along = flat_box((1.7, 1.9), (1.9, 2.2));
        for point in [
            p,
            DVec3::new(0.45, 1.95, 0.0),
            DVec3::new(0.75, 1.95, 0.0),
            DVec3::new(0.55, 0.15, 0.0),
            DVec3::new(0.95, 0.05, 0.0),
            DVec3::new(0.5, 1.0, 0.0),
        ] {
            let held = below.contains_periodic(point, &seams);
            assert_eq!(above.contains_periodic(point, &seams), held, "{point}");
            assert_eq!(along.contains_periodic(point, &seams), held, "{point}");
        }
        // (0.75, 1.95) is held through its image one period down, (0.45, −0.05); its
        // neighbour at x = 0.45 is not, though a plain image would put it at (0.45, −0.05).
        assert!(below.contains_periodic(DVec3::new(0.75, 1.95, 0.0), &seams));
        assert!(!below.contains_periodic(DVec3::new(0.45, 1.95, 0.0), &seams));
        assert!(below.contains_periodic(DVec3::new(0.45, 1.95, 0.0), &plain));
    }

    #[test]
    fn boxes_tiling_a_sheared_cell_share_a_branch_through_the_seam() {
        let seams = sheared_seams();
        // A branch from (0.6, 1.9) through the top face to (0.7, 2.1): its upper half lies
        // in the brick one up, whose points are those of the box at (x − 0.3, y − 2), so
        // the whole branch lies in the box frame at x ∈ [0.3, 0.4), y ∈ [−0.1, 0.1).
        let (a, b) = (DVec3::new(0.6, 1.9, 0.0), DVec3::new(0.7, 2.1, 0.0));
        let xs = [0.1, 0.35, 0.6, 0.85, 1.1];
        let ys = [-0.3, 0.7, 1.2, 1.7];
        let mut total = 0.0;
        for x in xs.windows(2) {
            for y in ys.windows(2) {
                let part =
                    flat_box((x[0], x[1]), (y[0], y[1])).periodic_segment_fraction(a, b, &seams);
                let expected = match (x[0], y[0]) {
                    (0.1, -0.3) | (0.35, -0.3) => 0.5,
                    _ => 0.0,
                };
                assert!(
                    (part - expected).abs() < 1e-15,
                    "[{}, {}) × [{}, {}): {part}",
                    x[0],
                    x[1],
                    y[0],
                    y[1]
                );
                total += part;
            }
        }
        assert!((total - 1.0).abs() < 1e-15, "{total}");
        // With plain images the branch would fall whole in [0.6, 0.85) × [1.7, 2.7).
        let plain = Seams {
            shear: None,
            ..seams
        };
        let f = flat_box((0.6, 0.85), (1.7, 2.7)).periodic_segment_fraction(a, b, &plain);
        assert!((f - 1.0).abs() < 1e-15);
        assert_eq!(
            flat_box((0.6, 0.85), (-0.3, 0.7)).periodic_segment_fraction(a, b, &seams),
            0.0
        );
    }

    #[test]
    fn a_flow_slab_of_a_sheared_box_is_its_gradient_period_as_sliding_bricks() {
        let seams = sheared_seams();
        let domain = Bounds {
            min: DVec3::new(0.0, 0.0, -0.5),
            max: DVec3::new(1.0, 2.0, 0.5),
        };
        let slab = RegionShape::Slab {
            axis: 0,
            min: 0.35,
            max: 0.6,
        };
        let boxes = region_boxes(&slab, &domain, 2, &seams);
        assert_eq!((boxes.clip.min.y, boxes.clip.max.y), (0.0, 2.0));
        assert!((boxes.volume.volume(2) - 0.25 * 2.0).abs() < 1e-15);
        // The upper half of the branch above, mapped into the box, is in the slab.
        let (a, b) = (DVec3::new(0.6, 1.9, 0.0), DVec3::new(0.7, 2.1, 0.0));
        assert!((boxes.fraction(a, b) - 0.5).abs() < 1e-15);
        assert!(boxes.holds(DVec3::new(0.4, 1.99, 0.0)));
        assert!(!boxes.holds(DVec3::new(0.7, 0.01, 0.0)));
        // A slab along the gradient is unaffected by the shift.
        let layer = RegionShape::Slab {
            axis: 1,
            min: 1.8,
            max: 2.2,
        };
        let boxes = region_boxes(&layer, &domain, 2, &seams);
        assert!((boxes.fraction(a, b) - 1.0).abs() < 1e-15);
        assert!(boxes.holds(DVec3::new(0.9, 0.1, 0.0)));
    }

    #[test]
    fn a_region_of_a_whole_period_is_unbounded_along_it() {
        let seams = Seams {
            axes: [false, false, true],
            length: DVec3::new(0.0, 0.0, 2.0),
            shear: None,
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
