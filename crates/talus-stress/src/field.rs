//! Coarse-grained fields on a grid (Goldhirsch 2010; Weinhart et al. 2012): density,
//! momentum density, velocity, kinetic stress and contact stress at the nodes of a grid
//! over the domain box, with a separable Gaussian kernel normalised exactly over the
//! grid nodes, so that the fields integrate to the totals (mass, momentum, Σ f ⊗ l) to
//! rounding. Kernel, normalisation, boundaries and seams: `docs/physics/stress.md` §10.

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use talus_contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus_core::prelude::*;
use talus_core::schedule::{Plugin, SimBuilder, Stage};

use crate::region::{Bounds, DomainInputs, Seams, ShearedSeam, grain_extent, sample_domain};
use crate::tensor::Tensor;

/// Name of the coarse-graining system in the plan.
pub const FIELD_SYSTEM_NAME: &str = "coarse_graining";

/// The kernel is cut at this many widths along each axis.
pub const CUTOFF_WIDTHS: f64 = 3.0;

/// Gauss–Legendre nodes on [0, 1] (three points, exact for polynomials of degree 5).
const GAUSS_NODES: [f64; 3] = [
    0.5 - 0.387_298_334_620_741_7,
    0.5,
    0.5 + 0.387_298_334_620_741_7,
];
/// Gauss–Legendre weights on [0, 1], summing to 1.
const GAUSS_WEIGHTS: [f64; 3] = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0];
/// Longest piece of a branch integrated by one three-point rule, in kernel widths.
const PIECE_WIDTHS: f64 = 0.5;
/// Most pieces a branch is cut into (a branch is at most half a box, so this only bounds
/// a pathological width far below the grain size).
const MAX_PIECES: usize = 256;

/// What to coarse-grain and how.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldSpec {
    /// Grid cells along x, y, z (z = 1 in 2-D); nodes are the cell centres.
    pub cells: [usize; 3],
    /// Kernel width w (standard deviation of the Gaussian along each axis), m.
    pub width: f64,
    /// Sample every this many steps (0 is treated as 1); step 0 is always sampled.
    pub every: u64,
}

/// The coarse-graining plugin: adds the [`sample_fields`] system to [`Stage::Sample`]
/// and the [`FieldSettings`] and [`FieldRecord`] resources. Build it only when fields
/// are wanted; without it nothing of this runs.
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseGrainingPlugin {
    /// The grid, kernel and interval.
    pub spec: FieldSpec,
}

impl Plugin for CoarseGrainingPlugin {
    fn name(&self) -> String {
        FIELD_SYSTEM_NAME.into()
    }

    fn build(&self, sim: &mut SimBuilder) {
        let mut spec = self.spec.clone();
        spec.every = spec.every.max(1);
        let [nx, ny, nz] = spec.cells;
        sim.note(format!(
            "coarse-grained fields every {} step(s): {nx} × {ny} × {nz} cells, Gaussian kernel of width {:.4e} m cut at {CUTOFF_WIDTHS} widths",
            spec.every, spec.width
        ));
        sim.world.insert_resource(FieldSettings { spec });
        sim.world.insert_resource(FieldRecord::default());
        sim.add_system(Stage::Sample, FIELD_SYSTEM_NAME, sample_fields);
    }
}

/// The field settings, inserted by [`CoarseGrainingPlugin`].
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct FieldSettings {
    /// Grid, kernel and interval.
    pub spec: FieldSpec,
}

/// The latest field sample, for the report and the recording.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct FieldRecord {
    /// The most recent sample, if one has been taken.
    pub latest: Option<FieldSample>,
    /// Number of samples taken so far (tells readers whether `latest` is new).
    pub taken: u64,
}

/// Coarse-grained fields at one instant, at the nodes of a grid over the domain box.
/// Node (i, j, k) is entry `i + nx (j + ny k)` of every list; it sits at the centre of its
/// cell, `min + (i + ½, j + ½, k + ½) · cell_size`. Stresses follow the conventions of
/// [`crate::RegionStress`] (Pa, tension positive).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldSample {
    /// Step at which it was taken.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Always `gaussian`: exp(−x²/2w²) per axis, cut at `cutoff`, normalised over the nodes.
    pub kernel: String,
    /// Kernel width w, m.
    pub width: f64,
    /// Cut-off distance along each axis, m (3 w).
    pub cutoff: f64,
    /// Cells along x, y, z.
    pub cells: [usize; 3],
    /// Lower corner of the grid (the domain box), m.
    pub min: [f64; 3],
    /// Upper corner of the grid, m.
    pub max: [f64; 3],
    /// Cell edges, m.
    pub cell_size: [f64; 3],
    /// Cell volume, m³ (2-D: area × 1 m).
    pub cell_volume: f64,
    /// Mass density ρ, kg/m³.
    pub density: Vec<f64>,
    /// Momentum density p = Σ m v φ, kg/(m² s); across a Lees–Edwards gradient seam a
    /// node sees the grain's image there, with its velocity v ± γ̇ L_g along the flow.
    pub momentum: Vec<[f64; 3]>,
    /// Velocity V = p / ρ, m/s (0 where ρ = 0).
    pub velocity: Vec<[f64; 3]>,
    /// Contact stress Σ_c f ⊗ l ∫₀¹ φ(r − x_a − s l) ds, Pa.
    pub contact_stress: Vec<Tensor>,
    /// Kinetic stress −Σ_p m_p v′_p ⊗ v′_p φ(r − x_p), v′_p = v_p − V(r), Pa.
    pub kinetic_stress: Vec<Tensor>,
    /// Pressure −tr(σ_contact + σ_kinetic) / D, Pa.
    pub pressure: Vec<f64>,
}

impl FieldSample {
    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.cells.iter().product()
    }

    /// Position of node `index`, m.
    pub fn node_position(&self, index: usize) -> DVec3 {
        let [nx, ny, _] = self.cells;
        let ijk = [index % nx, (index / nx) % ny, index / (nx * ny)];
        DVec3::from_array(std::array::from_fn(|d| {
            self.min[d] + (ijk[d] as f64 + 0.5) * self.cell_size[d]
        }))
    }
}

/// One axis of the grid, as the kernel sees it.
#[derive(Clone, Copy, Debug)]
struct Axis {
    min: f64,
    cell: f64,
    cells: usize,
    periodic: bool,
    /// The z axis of a 2-D scene: one node, every disk on it.
    flat: bool,
    width: f64,
}

impl Axis {
    /// The kernel's weights along this axis for a point at `x`: (node, weight / m,
    /// periods) with Σ weight × cell = 1 exactly up to rounding; `periods` is how many box
    /// lengths the node's unwrapped position lies above the box (−1 below it, 0 inside),
    /// i.e. the node sees the point's image shifted by −periods box lengths. Nodes within
    /// the cut-off get exp(−d²/2w²), d the distance to the point (along a periodic axis to
    /// each of its images within reach, which wraps the kernel round the seam); the
    /// weights are then divided by their sum × cell. Where no node is within reach (a point farther than
    /// the cut-off outside the grid, or a width below a sixth of a cell), the nearest
    /// node takes it all.
    fn weights(&self, x: f64, out: &mut Vec<(usize, f64, i64)>) {
        out.clear();
        if self.flat {
            out.push((0, 1.0 / self.cell, 0));
            return;
        }
        let reach = CUTOFF_WIDTHS * self.width;
        let n = self.cells as i64;
        let mut first = ((x - reach - self.min) / self.cell - 0.5).ceil() as i64;
        let mut last = ((x + reach - self.min) / self.cell - 0.5).floor() as i64;
        if !self.periodic {
            first = first.max(0);
            last = last.min(n - 1);
        }
        let mut sum = 0.0;
        for i in first..=last {
            let d = self.min + (i as f64 + 0.5) * self.cell - x;
            if d.abs() > reach {
                continue;
            }
            let g = (-0.5 * (d / self.width).powi(2)).exp();
            sum += g;
            out.push((i.rem_euclid(n) as usize, g, i.div_euclid(n)));
        }
        if sum > 0.0 {
            let scale = 1.0 / (sum * self.cell);
            for (_, w, _) in out.iter_mut() {
                *w *= scale;
            }
        } else {
            out.clear();
            let i = ((x - self.min) / self.cell).floor() as i64;
            let (i, periods) = if self.periodic {
                (i.rem_euclid(n), i.div_euclid(n))
            } else {
                (i.clamp(0, n - 1), 0)
            };
            out.push((i as usize, 1.0 / self.cell, periods));
        }
    }
}

/// Node accumulators of one sample.
#[derive(Default)]
pub struct FieldScratch {
    density: Vec<f64>,
    /// Σ m (v − u) φ, u the mean velocity of all grains.
    relative_momentum: Vec<DVec3>,
    /// Σ m (v − u) ⊗ (v − u) φ.
    relative_flux: Vec<Tensor>,
    contact: Vec<Tensor>,
    weights: KernelWeights,
}

/// Per-axis kernel weights of one point, and under shear the flow-axis weights of its
/// images one period down, in place and one period up the gradient axis.
#[derive(Default)]
struct KernelWeights {
    axes: [Vec<(usize, f64, i64)>; 3],
    /// Flow-axis weights at x_f − k Δ for k = −1, 0, 1 (entries k + 1).
    flow_images: [Vec<(usize, f64, i64)>; 3],
}

impl FieldScratch {
    /// Calls `add(node, φ(node − x), k)` for every node in reach of `x`; the weights φ
    /// sum to 1 / cell volume. Under Lees–Edwards shear a node across the gradient seam
    /// sees the image of `x` k periods down (k = ±1: at x − k (L_g e_g + Δ e_f)), so its
    /// flow-axis weight is taken at x_f − k Δ; k = 0 elsewhere and without shear.
    fn deposit(
        axes: &[Axis; 3],
        weights: &mut KernelWeights,
        shear: Option<ShearedSeam>,
        x: DVec3,
        mut add: impl FnMut(usize, f64, i64),
    ) {
        let (nx, ny) = (axes[0].cells, axes[1].cells);
        let Some(shear) = shear else {
            for d in 0..3 {
                axes[d].weights(x[d], &mut weights.axes[d]);
            }
            let w = &weights.axes;
            for &(k, wz, _) in &w[2] {
                for &(j, wy, _) in &w[1] {
                    let wyz = wy * wz;
                    let row = nx * (j + ny * k);
                    for &(i, wx, _) in &w[0] {
                        add(row + i, wx * wyz, 0);
                    }
                }
            }
            return;
        };
        let (f, g) = (shear.flow, shear.gradient);
        let other = 3 - f - g;
        axes[g].weights(x[g], &mut weights.axes[g]);
        axes[other].weights(x[other], &mut weights.axes[other]);
        // The flow weights of each image the gradient nodes see (the kernel reaches less
        // than half a period, so at most one seam: k ∈ {−1, 0, 1}).
        for k in -1..=1i64 {
            let list = &mut weights.flow_images[(k + 1) as usize];
            list.clear();
            if weights.axes[g].iter().any(|e| e.2 == k) {
                axes[f].weights(x[f] - k as f64 * shear.offset, list);
            }
        }
        let mut node = [0usize; 3];
        for &(jg, wg, k) in &weights.axes[g] {
            node[g] = jg;
            let flow = &weights.flow_images[(k.clamp(-1, 1) + 1) as usize];
            for &(jo, wo, _) in &weights.axes[other] {
                node[other] = jo;
                let wgo = wg * wo;
                for &(jf, wf, _) in flow {
                    node[f] = jf;
                    add(node[0] + nx * (node[1] + ny * node[2]), wf * wgo, k);
                }
            }
        }
    }
}

/// Grain data the coarse-graining reads.
type FieldGrainQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Position,
        &'static Velocity,
        &'static Radius,
        &'static Mass,
    ),
    With<Grain>,
>;

/// The coarse-graining system, in [`Stage::Sample`]: on steps that are multiples of the
/// interval, computes the fields on the grid over this step's domain box and stores them
/// in [`FieldRecord`]. It sees the same state as [`crate::sample_stress`]: positions and
/// contact forces of this step's force evaluation, full-step velocities. Sums run in
/// query order, so a sample is bit-reproducible.
#[allow(clippy::too_many_arguments)]
pub fn sample_fields(
    clock: Res<Clock>,
    config: Res<SimConfig>,
    snapshot: Res<GrainSnapshot>,
    settings: Res<FieldSettings>,
    mut record: ResMut<FieldRecord>,
    mut scratch: Local<FieldScratch>,
    grains: FieldGrainQuery,
    contacts: Query<(&Contact, &ContactGeometry, &ContactForce)>,
) {
    let spec = &settings.spec;
    if !clock.step.is_multiple_of(spec.every.max(1)) {
        return;
    }
    let dims = config.dimension.as_number() as usize;

    // The grid: the domain box of the stress sampler.
    let mut total_mass = 0.0;
    let mut total_momentum = DVec3::ZERO;
    for (_, v, _, m) in &grains {
        total_mass += m.0;
        total_momentum += m.0 * v.0;
    }
    let (grain_min, grain_max) = grain_extent(grains.iter().map(|(p, _, r, _)| (p.0, r.0)));
    let domain = sample_domain(
        &DomainInputs {
            walls: &snapshot.walls,
            grain_min,
            grain_max,
            dims,
        },
        snapshot.periodic(),
    );
    let mut cells = spec.cells.map(|c| c.max(1));
    if dims == 2 {
        cells[2] = 1;
    }
    let periodic = snapshot.periodic().map_or([false; 3], |b| b.axes);
    let shear = Seams::of(snapshot.periodic()).shear;
    // The velocity of the image one period up the gradient axis beyond the grain's own,
    // γ̇ L_g e_f (zero without shear).
    let image_velocity = shear.map_or(DVec3::ZERO, |s| {
        let mut w = DVec3::ZERO;
        w[s.flow] = s.image_speed;
        w
    });
    let axes: [Axis; 3] = std::array::from_fn(|d| Axis {
        min: domain.min[d],
        cell: (domain.max[d] - domain.min[d]) / cells[d] as f64,
        cells: cells[d],
        periodic: periodic[d],
        flat: dims == 2 && d == 2,
        width: spec.width,
    });
    let nodes: usize = cells.iter().product();
    let degenerate = axes.iter().any(|a| !(a.cell.is_finite() && a.cell > 0.0));

    let FieldScratch {
        density,
        relative_momentum,
        relative_flux,
        contact,
        weights,
    } = &mut *scratch;
    density.clear();
    density.resize(nodes, 0.0);
    relative_momentum.clear();
    relative_momentum.resize(nodes, DVec3::ZERO);
    relative_flux.clear();
    relative_flux.resize(nodes, Tensor::ZERO);
    contact.clear();
    contact.resize(nodes, Tensor::ZERO);

    if !degenerate {
        // Velocities relative to the mean of all grains: the kinetic stress is the same
        // for any reference, and a bulk motion then costs no precision.
        let reference = if total_mass > 0.0 {
            total_momentum / total_mass
        } else {
            DVec3::ZERO
        };
        for (p, v, _, m) in &grains {
            let own = v.0 - reference;
            FieldScratch::deposit(&axes, weights, shear, p.0, |n, phi, k| {
                // A node across the sheared seam sees the image k periods down, which
                // moves at v − k γ̇ L_g e_f.
                let dv = if k == 0 {
                    own
                } else {
                    v.0 - k as f64 * image_velocity - reference
                };
                let mphi = m.0 * phi;
                density[n] += mphi;
                relative_momentum[n] += mphi * dv;
                relative_flux[n].add_outer(dv, dv, mphi);
            });
        }
        for (c, g, f) in &contacts {
            if f.force == DVec3::ZERO {
                continue;
            }
            let Some(i) = snapshot.dense(c.a) else {
                continue;
            };
            let xa = snapshot.position(i);
            let far = match c.kind {
                ContactKind::GrainGrain => {
                    let Some(j) = snapshot.dense(c.b) else {
                        continue;
                    };
                    // The image of b nearest to a, as in the Love–Weber sum.
                    xa - snapshot.separation(xa, snapshot.position(j))
                }
                // A wall has no centre: the branch ends at the contact point.
                ContactKind::GrainWall => g.point(xa, snapshot.radius(i)),
            };
            let branch = far - xa;
            let pieces = ((branch.length() / (PIECE_WIDTHS * spec.width)).ceil() as usize)
                .clamp(1, MAX_PIECES);
            for piece in 0..pieces {
                for (s, w) in GAUSS_NODES.iter().zip(GAUSS_WEIGHTS) {
                    let t = (piece as f64 + s) / pieces as f64;
                    let weight = w / pieces as f64;
                    FieldScratch::deposit(&axes, weights, shear, xa + t * branch, |n, phi, _| {
                        contact[n].add_outer(f.force, branch, weight * phi);
                    });
                }
            }
        }
    }

    // Results, written into the previous sample's storage.
    let cell_volume = Bounds {
        min: DVec3::ZERO,
        max: DVec3::from_array(std::array::from_fn(|d| axes[d].cell)),
    }
    .volume(3);
    let sample = record.latest.get_or_insert_with(|| FieldSample {
        step: 0,
        time: 0.0,
        kernel: "gaussian".into(),
        width: 0.0,
        cutoff: 0.0,
        cells,
        min: [0.0; 3],
        max: [0.0; 3],
        cell_size: [0.0; 3],
        cell_volume: 0.0,
        density: Vec::new(),
        momentum: Vec::new(),
        velocity: Vec::new(),
        contact_stress: Vec::new(),
        kinetic_stress: Vec::new(),
        pressure: Vec::new(),
    });
    sample.step = clock.step;
    sample.time = clock.time;
    sample.width = spec.width;
    sample.cutoff = CUTOFF_WIDTHS * spec.width;
    sample.cells = cells;
    sample.min = domain.min.to_array();
    sample.max = domain.max.to_array();
    sample.cell_size = std::array::from_fn(|d| axes[d].cell);
    sample.cell_volume = cell_volume;
    let reference = if total_mass > 0.0 {
        total_momentum / total_mass
    } else {
        DVec3::ZERO
    };
    sample.density.clone_from(density);
    sample.momentum.clear();
    sample.velocity.clear();
    sample.kinetic_stress.clear();
    sample.pressure.clear();
    for n in 0..nodes {
        let rho = density[n];
        let (velocity, kinetic) = if rho > 0.0 {
            // Σ m v′v′φ with v′ = v − V(r): Σ m (v−u)(v−u)φ − ρ (V−u)(V−u).
            let drift = relative_momentum[n] / rho;
            let mut flux = relative_flux[n];
            flux.add_outer(drift, drift, -rho);
            (reference + drift, flux.scaled(-1.0))
        } else {
            (DVec3::ZERO, Tensor::ZERO)
        };
        sample
            .momentum
            .push((rho * reference + relative_momentum[n]).to_array());
        sample.velocity.push(velocity.to_array());
        sample.kinetic_stress.push(kinetic);
        sample
            .pressure
            .push(-(contact[n].trace(dims) + kinetic.trace(dims)) / dims as f64);
    }
    sample.contact_stress.clone_from(contact);
    record.taken += 1;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_weights_sum_to_one_over_a_cell_and_wrap_round_the_seam() {
        let axis = Axis {
            min: 0.0,
            cell: 0.1,
            cells: 10,
            periodic: true,
            flat: false,
            width: 0.07,
        };
        let mut out = Vec::new();
        for x in [0.0, 0.01, 0.55, 0.99, -0.02, 1.03] {
            axis.weights(x, &mut out);
            let total: f64 = out.iter().map(|(_, w, _)| w * axis.cell).sum();
            assert!((total - 1.0).abs() < 1e-15, "{x}: {total}");
            // Near the seam both ends of the grid take a share.
            if !(0.02..=0.98).contains(&x) {
                assert!(out.iter().any(|(i, _, _)| *i == 0) && out.iter().any(|(i, _, _)| *i == 9));
            }
        }
        // Symmetric about a point midway between nodes across the seam.
        axis.weights(0.0, &mut out);
        let weight_of = |i: usize| out.iter().find(|(k, _, _)| *k == i).unwrap().1;
        assert!((weight_of(0) - weight_of(9)).abs() < 1e-12);
        assert!((weight_of(1) - weight_of(8)).abs() < 1e-12);

        // A wall-bounded axis keeps the mass of a point at its edge on its nodes.
        let bounded = Axis {
            periodic: false,
            ..axis
        };
        for x in [0.0, 0.001, 1.0, 1.2, -5.0] {
            bounded.weights(x, &mut out);
            let total: f64 = out.iter().map(|(_, w, _)| w * bounded.cell).sum();
            assert!((total - 1.0).abs() < 1e-15, "{x}: {total}");
            assert!(out.iter().all(|(i, _, _)| *i < 10));
        }
    }

    #[test]
    fn far_from_the_edges_the_weights_are_the_sampled_gaussian() {
        let axis = Axis {
            min: 0.0,
            cell: 0.01,
            cells: 200,
            periodic: false,
            flat: false,
            width: 0.05,
        };
        let mut out = Vec::new();
        axis.weights(1.0, &mut out);
        // Node spacing w/5: the sampled Gaussian cut at 3 w sums to √(2π) w / cell × (1 −
        // 2.7e-3) within 1e-12; the normalised weights then match φ to that factor.
        let (i, w, _) = out.iter().find(|(i, _, _)| *i == 99).copied().unwrap();
        let d = (i as f64 + 0.5) * axis.cell - 1.0;
        let gauss = (-0.5 * (d / axis.width).powi(2)).exp()
            / ((2.0 * std::f64::consts::PI).sqrt() * axis.width);
        let truncation = ERF_3_OVER_SQRT2;
        assert!(
            (w * truncation / gauss - 1.0).abs() < 1e-3,
            "{w} vs {gauss}"
        );
    }

    #[test]
    fn across_the_sheared_seam_a_node_sees_the_image_shifted_along_the_flow() {
        // 2-D, flow x over [0, 1), gradient y over [0, 2), 10 × 20 cells of 0.1, w = 0.07,
        // offset Δ = 0.3. A point at (0.5, 1.98): the nodes past the top face (wrapped to
        // the bottom rows) see its image one period down, at (0.2, −0.02).
        let axis = |cells: usize, periodic: bool, flat: bool| Axis {
            min: if flat { -0.5 } else { 0.0 },
            cell: if flat { 1.0 } else { 0.1 },
            cells,
            periodic,
            flat,
            width: 0.07,
        };
        let axes = [
            axis(10, true, false),
            axis(20, true, false),
            axis(1, false, true),
        ];
        let shear = ShearedSeam {
            flow: 0,
            gradient: 1,
            offset: 0.3,
            image_speed: 0.0,
        };
        let mut weights = KernelWeights::default();
        let mut deposits = Vec::new();
        FieldScratch::deposit(
            &axes,
            &mut weights,
            Some(shear),
            DVec3::new(0.5, 1.98, 0.0),
            |n, phi, k| deposits.push((n, phi, k)),
        );
        let cell_volume = 0.1 * 0.1 * 1.0;
        let total: f64 = deposits.iter().map(|d| d.1).sum::<f64>() * cell_volume;
        assert!((total - 1.0).abs() < 1e-15, "{total}");
        // Per image: the share and the mean node position along x.
        for (k, centre, rows) in [(0i64, 0.5, 14..20), (1, 0.2, 0..3)] {
            let mine: Vec<_> = deposits.iter().filter(|d| d.2 == k).collect();
            assert!(!mine.is_empty());
            let share: f64 = mine.iter().map(|d| d.1).sum();
            let mean_x: f64 = mine
                .iter()
                .map(|d| d.1 * ((d.0 % 10) as f64 + 0.5) * 0.1)
                .sum::<f64>()
                / share;
            // Nodes at 0.05 + 0.1 i are symmetric about 0.5 and about 0.2 (both halfway
            // between two nodes), and the kernel does not reach round the flow axis.
            assert!((mean_x - centre).abs() < 1e-12, "k = {k}: {mean_x}");
            assert!(mine.iter().all(|d| rows.contains(&(d.0 / 10))), "k = {k}");
        }
        // Without shear the bottom rows see the plain image, centred at x = 0.5.
        deposits.clear();
        FieldScratch::deposit(
            &axes,
            &mut weights,
            None,
            DVec3::new(0.5, 1.98, 0.0),
            |n, phi, k| deposits.push((n, phi, k)),
        );
        let bottom: Vec<_> = deposits.iter().filter(|d| d.0 / 10 < 3).collect();
        let share: f64 = bottom.iter().map(|d| d.1).sum();
        let mean_x: f64 = bottom
            .iter()
            .map(|d| d.1 * ((d.0 % 10) as f64 + 0.5) * 0.1)
            .sum::<f64>()
            / share;
        assert!((mean_x - 0.5).abs() < 1e-12);
    }

    /// erf(3/√2), the mass of a Gaussian within 3 standard deviations.
    const ERF_3_OVER_SQRT2: f64 = 0.997_300_203_936_739_8;
}
