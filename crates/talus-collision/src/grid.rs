//! The broad phase: grains binned into a uniform grid by a counting sort.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use talus_core::counting::counting_sort;
use talus_core::periodic::{LeesEdwards, PeriodicBox};
use talus_core::snapshot::GrainSnapshot;

/// Grains binned into cubic cells, rebuilt every step. Cells are stored densely
/// (x fastest); `sorted[cell_start[c]..cell_start[c + 1]]` are the grains of cell `c`.
#[derive(Resource, Clone, Debug, Default)]
pub struct CellGrid {
    /// Lower corner of cell (0, 0, 0).
    pub origin: DVec3,
    /// Cell edge along each axis, m (cubic cells, except along periodic axes, where the
    /// box length is divided into a whole number of cells).
    pub cell: DVec3,
    /// Which axes wrap around (periodic box).
    pub periodic: [bool; 3],
    /// Cells along x, y, z.
    pub dims: [usize; 3],
    /// Start of each cell's run in `sorted`, plus one final entry.
    pub cell_start: Vec<u32>,
    /// Dense grain indices sorted by cell.
    pub sorted: Vec<u32>,
    /// Cell of each grain.
    pub cell_of: Vec<u32>,
    /// Interaction range beyond touch (r_c), m. Default: 0.
    pub interaction_range: f64,
}

/// Grains a job of the grid's parallel passes takes at the least.
const GRID_CHUNK: usize = 4096;

impl CellGrid {
    /// Cell coordinates of a position (clamped into the grid).
    #[inline]
    pub fn coords(&self, p: DVec3) -> [usize; 3] {
        let q = (p - self.origin) / self.cell;
        [
            (q.x.max(0.0) as usize).min(self.dims[0] - 1),
            (q.y.max(0.0) as usize).min(self.dims[1] - 1),
            (q.z.max(0.0) as usize).min(self.dims[2] - 1),
        ]
    }

    /// Dense cell index.
    #[inline]
    pub fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Grains of a cell.
    #[inline]
    pub fn cell_grains(&self, cell: usize) -> &[u32] {
        &self.sorted[self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize]
    }

    /// Where the grains of the cells `first..=last` (dense cell indices) lie in
    /// `sorted`: one run, `start..end`.
    #[inline]
    pub fn cells_span(&self, first: usize, last: usize) -> (usize, usize) {
        (
            self.cell_start[first] as usize,
            self.cell_start[last + 1] as usize,
        )
    }

    /// Rebuilds the grid over the grains of a snapshot.
    pub fn rebuild(&mut self, s: &GrainSnapshot) {
        self.rebuild_with_margin(s, 0.0);
    }

    /// Rebuilds the grid with cells at least 2 R_max + r_c + `margin` long (the margin is
    /// a neighbour list's skin).
    pub fn rebuild_with_margin(&mut self, s: &GrainSnapshot, margin: f64) {
        let n = s.len();
        // Minima and maxima are exact, so the chunks' bounds combine to the same bits in
        // any order.
        let bounds = |records: &[talus_core::snapshot::GrainRecord]| {
            records.iter().fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), g| (lo.min(g.position), hi.max(g.position)),
            )
        };
        let (mut lo, mut hi) = s.records.par_chunks(GRID_CHUNK).map(bounds).reduce(
            || (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo_a, hi_a), (lo_b, hi_b)| (lo_a.min(lo_b), hi_a.max(hi_b)),
        );
        if n == 0 || !lo.is_finite() || !hi.is_finite() {
            lo = DVec3::ZERO;
            hi = DVec3::ZERO;
        }
        // Edge ≥ 2 R_max + r_c so that touching grains are never more than one cell apart.
        let edge = (2.0 * s.max_radius + self.interaction_range + margin).max(1e-12) * (1.0 + 1e-9);
        self.periodic = s.periodic().map_or([false; 3], |b| b.axes);
        if let Some(b) = s.periodic() {
            for a in 0..3 {
                if b.axes[a] {
                    lo[a] = b.lo[a];
                    hi[a] = b.hi[a];
                }
            }
        }
        let extent = hi - lo;
        // Bound the cell count (a grain flung far away must not blow up memory).
        let max_cells = (8 * n).max(4096) as f64;
        let mut scale = 1.0;
        loop {
            let mut cells = DVec3::ONE;
            let mut size = DVec3::splat(edge * scale);
            for a in 0..3 {
                if self.periodic[a] {
                    // A whole number of cells, each at least `edge` long.
                    cells[a] = (extent[a] / (edge * scale)).floor().max(1.0);
                    size[a] = extent[a] / cells[a];
                } else {
                    cells[a] = (extent[a] / (edge * scale)).floor() + 1.0;
                }
            }
            if cells.x * cells.y * cells.z <= max_cells {
                self.dims = [cells.x as usize, cells.y as usize, cells.z as usize];
                self.cell = size;
                break;
            }
            scale *= 1.5;
        }
        self.origin = lo;
        let cell = self.cell;
        let total = self.dims[0] * self.dims[1] * self.dims[2];
        let dims = self.dims;
        let cell_of = |g: &talus_core::snapshot::GrainRecord| {
            let q = (g.position - lo) / cell;
            let c = [
                (q.x as usize).min(dims[0] - 1),
                (q.y as usize).min(dims[1] - 1),
                (q.z as usize).min(dims[2] - 1),
            ];
            (c[0] + dims[0] * (c[1] + dims[1] * c[2])) as u32
        };
        self.cell_of.clear();
        self.cell_of
            .par_extend(s.records.par_iter().with_min_len(GRID_CHUNK).map(cell_of));
        self.sorted.clear();
        self.sorted.resize(n, 0);
        // Stable: within a cell grains stay sorted by dense index.
        let cells = &self.cell_of;
        counting_sort(
            n,
            total,
            |i| cells[i] as usize,
            &mut self.cell_start,
            &mut self.sorted,
        );
    }
}

/// The distinct cells next to (and including) one cell coordinate along one axis:
/// clamped at the grid's ends, wrapped around along a periodic axis (where a grid of one
/// or two cells lists each cell once, so that no pair is found twice).
pub struct Neighbours {
    cells: [usize; 3],
    len: usize,
}

impl Neighbours {
    /// The cells.
    #[inline]
    pub fn cells(&self) -> &[usize] {
        &self.cells[..self.len]
    }
}

impl CellGrid {
    /// The cells next to cell coordinate `c[axis]` along `axis`, itself included.
    #[inline]
    pub fn neighbour_cells(&self, c: [usize; 3], axis: usize) -> Neighbours {
        let n = self.dims[axis];
        let k = c[axis];
        if self.periodic[axis] {
            match n {
                1 => Neighbours {
                    cells: [0, 0, 0],
                    len: 1,
                },
                2 => Neighbours {
                    cells: [0, 1, 0],
                    len: 2,
                },
                _ => Neighbours {
                    cells: [(k + n - 1) % n, k, (k + 1) % n],
                    len: 3,
                },
            }
        } else {
            let lo = k.saturating_sub(1);
            let hi = (k + 1).min(n - 1);
            let mut cells = [0; 3];
            for (slot, cell) in cells.iter_mut().zip(lo..=hi) {
                *slot = cell;
            }
            Neighbours {
                cells,
                len: hi - lo + 1,
            }
        }
    }
}

/// Up to nine distinct cells along the flow axis of a Lees–Edwards box (see
/// [`CellGrid::sheared_flow_cells`]).
pub struct FlowCells {
    cells: [usize; 9],
    len: usize,
}

impl FlowCells {
    /// The cells, sorted, each once.
    #[inline]
    pub fn cells(&self) -> &[usize] {
        &self.cells[..self.len]
    }

    fn push_around(&mut self, grid: &CellGrid, flow: usize, k: usize) {
        let around = grid.neighbour_cells(
            {
                let mut c = [0; 3];
                c[flow] = k;
                c
            },
            flow,
        );
        for &cell in around.cells() {
            self.cells[self.len] = cell;
            self.len += 1;
        }
    }
}

impl CellGrid {
    /// The flow-axis cells to search, in a Lees–Edwards box, for partners of a grain at
    /// `p` (cell `c`) among the grains of gradient-axis cell `cg` (one of the gradient
    /// neighbours of `c`). A partner reached without crossing the gradient seam lies
    /// within one flow cell of the grain; one reached through the top seam (grain in the
    /// top gradient cell, partner in the bottom one) lies within one cell of x_f − Δ, and
    /// through the bottom seam of x_f + Δ, since its nearest image is shifted by ±Δ. With
    /// one or two gradient cells several of these hold at once; each cell is listed once.
    pub fn sheared_flow_cells(
        &self,
        b: &PeriodicBox,
        shear: &LeesEdwards,
        p: DVec3,
        c: [usize; 3],
        cg: usize,
    ) -> FlowCells {
        let (g, f) = (shear.gradient, shear.flow);
        let (k, n) = (c[g], self.dims[g]);
        let mut out = FlowCells {
            cells: [0; 9],
            len: 0,
        };
        let flow_cell = |x: f64| {
            let mut q = p;
            q[f] = x;
            self.coords(b.wrap(q))[f]
        };
        if cg + 1 >= k && cg <= k + 1 {
            out.push_around(self, f, c[f]);
        }
        if k == n - 1 && cg == 0 {
            out.push_around(self, f, flow_cell(p[f] - shear.offset));
        }
        if k == 0 && cg == n - 1 {
            out.push_around(self, f, flow_cell(p[f] + shear.offset));
        }
        let cells = &mut out.cells[..out.len];
        cells.sort_unstable();
        let mut len = 0;
        for i in 0..cells.len() {
            if i == 0 || cells[i] != cells[len - 1] {
                cells[len] = cells[i];
                len += 1;
            }
        }
        out.len = len;
        out
    }
}
