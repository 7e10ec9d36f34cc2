//! Verlet neighbour lists with a skin: candidate pairs within reach + skin are found on
//! the cell grid only when some grain has moved more than half the skin since the last
//! build; every other step tests just those candidates. Exact: a pair that comes within
//! reach must have been within reach + skin at the last build, since neither grain has
//! moved more than skin/2.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use talus_core::periodic::{LeesEdwards, PeriodicBox};
use talus_core::snapshot::GrainSnapshot;

use crate::grid::CellGrid;

/// Grains per parallel work unit; fixed so that results do not depend on the thread count.
pub const CHUNK: usize = 256;

/// Skin as a fraction of the largest diameter (LAMMPS's chute benchmark: 0.1 of d).
pub const SKIN_FRACTION: f64 = 0.1;

/// Candidate pairs of the last build and what they were built from.
#[derive(Resource, Default)]
pub struct NeighbourList {
    /// Skin beyond the reach, m (set at each build from the largest radius).
    pub skin: f64,
    /// Candidate partners, per chunk of [`CHUNK`] grains: (i, j) dense indices with
    /// j > i, in increasing i.
    pub chunks: Vec<Vec<(u32, u32)>>,
    /// Grain positions at the last build.
    reference: Vec<DVec3>,
    /// The snapshot layout ([`GrainSnapshot::layout`]) of the last build (0: none).
    layout: u32,
    /// Number of builds so far.
    pub builds: u64,
    /// Lees–Edwards image offset at the last build, m (0 without shear).
    offset: f64,
}

impl NeighbourList {
    /// Forces a rebuild at the next broad phase (the result must not change: the list is
    /// only a superset of the touching pairs).
    pub fn invalidate(&mut self) {
        self.layout = 0;
    }

    /// Whether the list must be rebuilt: first use, a changed set or order of grains or
    /// walls (the snapshot's layout), or a grain that moved more than half the skin.
    fn stale(&self, s: &GrainSnapshot) -> bool {
        if self.layout != s.layout {
            return true;
        }
        // Across a Lees–Edwards seam a pair's separation also changes with the image
        // offset: exact as long as 2 × (largest move) + |change of Δ| stays within the skin.
        let mut half = 0.5 * self.skin;
        if let Some(b) = &s.periodic
            && let Some(shear) = &b.shear
        {
            let lf = b.length()[shear.flow];
            let mut shift = (shear.offset - self.offset).abs();
            if shift > 0.5 * lf {
                shift = lf - shift;
            }
            half = 0.5 * (self.skin - shift);
            if half <= 0.0 {
                return true;
            }
        }
        let limit = half * half;
        s.position
            .par_iter()
            .with_min_len(4096)
            .zip(self.reference.par_iter())
            .any(|(p, q)| s.separation(*p, *q).length_squared() > limit)
    }
}

/// Broad phase: rebuilds the cell grid and the candidate pairs when the list is stale.
pub fn update_neighbour_list(
    snapshot: Res<GrainSnapshot>,
    mut grid: ResMut<CellGrid>,
    mut list: ResMut<NeighbourList>,
) {
    let s = &*snapshot;
    if !list.stale(s) {
        return;
    }
    let skin = SKIN_FRACTION * 2.0 * s.max_radius;
    list.skin = skin;
    let range = grid.interaction_range;
    grid.rebuild_with_margin(s, skin);
    let grid = &*grid;
    let n = s.len();
    let chunks = n.div_ceil(CHUNK);
    let list = &mut *list;
    if list.chunks.len() < chunks {
        list.chunks.resize_with(chunks, Vec::new);
    }
    list.chunks.truncate(chunks);
    list.chunks
        .par_iter_mut()
        .enumerate()
        .for_each(|(chunk, out)| {
            out.clear();
            for i in chunk * CHUNK..((chunk + 1) * CHUNK).min(n) {
                let p = s.position[i];
                let r = s.radius[i];
                let c = grid.coords(p);
                if let Some(b) = &s.periodic
                    && let Some(shear) = &b.shear
                {
                    sheared_candidates(s, grid, b, shear, i, c, range + skin, out);
                    continue;
                }
                let [xs, ys, zs] = [0, 1, 2].map(|a| grid.neighbour_cells(c, a));
                for &cz in zs.cells() {
                    for &cy in ys.cells() {
                        for &cx in xs.cells() {
                            for &j in grid.cell_grains(grid.index([cx, cy, cz])) {
                                if (j as usize) <= i {
                                    continue;
                                }
                                let reach = r + s.radius[j as usize] + range + skin;
                                let d = s.separation(p, s.position[j as usize]);
                                if d.length_squared() < reach * reach {
                                    out.push((i as u32, j));
                                }
                            }
                        }
                    }
                }
            }
            // Within a chunk, keep the pairs of each grain in increasing partner order, so
            // that the touching pairs come out in a fixed order.
            out.sort_unstable();
        });
    list.reference.clear();
    list.reference.extend_from_slice(&s.position);
    list.layout = s.layout;
    list.offset = s
        .periodic
        .and_then(|b| b.shear)
        .map_or(0.0, |shear| shear.offset);
    list.builds += 1;
}

/// Candidate partners j > i of grain `i` (in cell `c`) in a Lees–Edwards box: the plain
/// stencil along the third axis and the gradient axis, and along the flow axis the cells
/// of [`CellGrid::sheared_flow_cells`], which follow the shifted seam.
#[allow(clippy::too_many_arguments)]
fn sheared_candidates(
    s: &GrainSnapshot,
    grid: &CellGrid,
    b: &PeriodicBox,
    shear: &LeesEdwards,
    i: usize,
    c: [usize; 3],
    extra: f64,
    out: &mut Vec<(u32, u32)>,
) {
    let (g, f) = (shear.gradient, shear.flow);
    let third = 3 - g - f;
    let p = s.position[i];
    let r = s.radius[i];
    let gs = grid.neighbour_cells(c, g);
    let ts = grid.neighbour_cells(c, third);
    for &cg in gs.cells() {
        let fs = grid.sheared_flow_cells(b, shear, p, c, cg);
        for &ct in ts.cells() {
            for &cf in fs.cells() {
                let mut cell = [0; 3];
                cell[g] = cg;
                cell[f] = cf;
                cell[third] = ct;
                for &j in grid.cell_grains(grid.index(cell)) {
                    if (j as usize) <= i {
                        continue;
                    }
                    let reach = r + s.radius[j as usize] + extra;
                    let d = s.separation(p, s.position[j as usize]);
                    if d.length_squared() < reach * reach {
                        out.push((i as u32, j));
                    }
                }
            }
        }
    }
}
