//! LAMMPS's chute algorithm (`bench/in.chute`) written out as one plain Rust kernel over
//! the state Talus builds for `scenes/bench/chute.ron`: `gran/hooke/history` with
//! `newton on`, `nve/sphere`, `fix gravity` and `fix freeze` as LAMMPS's sources write
//! them, over a half neighbour list with a skin of 0.1, the tangential histories carried
//! from list to list by partner. Its [`Variant`]s: LAMMPS's algorithm as it stands; the
//! same with Talus's staleness test; that one split into Talus's passes (tests, forces,
//! sums); the second evaluating Talus's own linear law with Talus's contact life cycle; and
//! that one testing only a prefix of each grain's partners, as Talus's narrow phase does.
//! `benches/lammps_kernel.rs` races them against Talus's step; `tests/reference_chute.rs`
//! checks Talus's step against the one with Talus's law.

use std::time::Instant;

use glam::DVec3;
use talus::contact::{ContactKinematicsLanes, ContactLaw, SpinLanes};
use talus::core::lanes::{F4, V4};
use talus::core::snapshot::GrainSnapshot;
use talus_linear_spring::{LinearParams, LinearSpring, NormalDamping, TangentialSpring};

/// `bench/in.chute`'s constants (reduced units).
pub const TIME_STEP: f64 = 1e-4;
const NORMAL_STIFFNESS: f64 = 2e5;
const TANGENTIAL_STIFFNESS: f64 = 2.0 / 7.0 * NORMAL_STIFFNESS;
const NORMAL_DAMPING: f64 = 50.0;
const FRICTION: f64 = 0.5;
const SKIN: f64 = 0.1;
/// `INERTIA` of LAMMPS's `fix nve/sphere`: a solid sphere's 2/5.
const INERTIA: f64 = 0.4;

/// LAMMPS's thermo output for `bench/in.chute` at step 100: Σ½mv² and Σ½Iω².
pub const LAMMPS_STEP_100: (f64, f64) = (784292.08, 1571.0968);

/// Talus's own step-100 energies for the chute (`docs/performance.md`, "Same physics as
/// LAMMPS"; `tests/chute.rs`): what the kernel with Talus's law must give.
pub const TALUS_STEP_100: (f64, f64) = (784291.8947423529, 1571.2691153341918);

/// Which law a kernel evaluates, and with which staleness test.
#[derive(Clone, Copy, PartialEq)]
pub enum Variant {
    /// LAMMPS's algorithm as it stands.
    Plain,
    /// LAMMPS's algorithm with the list's staleness judged by Talus's bound on the moves
    /// about their common part (fewer builds, the same results).
    Refined,
    /// The refined kernel's work in Talus's passes instead of one: the overlap tests list
    /// the touching pairs; the force loop over that list keeps each pair's force and both
    /// torques in a record of its own (72 bytes, as Talus's `ContactForce`); the sums then
    /// add the records to the grains' totals in the same order as the refined kernel adds
    /// them (the same bits). What the single pass is worth, apart from the bytes and the
    /// law.
    Passes,
    /// The refined kernel evaluating Talus's linear law (`talus_linear_spring`, its lane
    /// form, four contacts at a time) with Talus's contact life cycle: a contact made
    /// where a pair first touches, evaluated while it touches and once more after it parts
    /// if it carried a force, its history (the law's state, the last normal and overlap)
    /// kept in the list's entry.
    TalusLaw,
    /// The Talus-law kernel testing, like Talus's narrow phase, only the pairs whose gap at
    /// the build the moves since can have closed: each grain's partners in order of that
    /// gap (live contacts first), a prefix of them tested, up to the largest bound so far
    /// of the moves of its block of `BLOCK_GRAINS` grains against its partners' blocks'
    /// (`BlockMoves::pair_bound` in Talus).
    TalusLawPruned,
}

impl Variant {
    /// Every variant, in the order the bench reports them.
    pub const ALL: [Variant; 5] = [
        Variant::Plain,
        Variant::Refined,
        Variant::Passes,
        Variant::TalusLaw,
        Variant::TalusLawPruned,
    ];

    /// The variant's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Plain => "plain",
            Variant::Refined => "refined",
            Variant::Passes => "three-pass",
            Variant::TalusLaw => "Talus-law",
            Variant::TalusLawPruned => "pruned Talus-law",
        }
    }

    /// Whether the kernel evaluates Talus's law.
    pub fn talus_law(self) -> bool {
        matches!(self, Variant::TalusLaw | Variant::TalusLawPruned)
    }
}

/// Grains of a block whose moves bound its pairs' closing (the pruned kernel), as Talus's
/// neighbour list's chunks.
const BLOCK_GRAINS: usize = 256;

/// A contact's history under Talus's law, kept in its neighbour-list entry.
#[derive(Clone, Copy, Default)]
struct TalusHistory {
    spring: TangentialSpring,
    /// Normal and overlap of the last evaluation (`ContactKinematics::set_displacement`).
    normal: DVec3,
    overlap: f64,
}

/// A contact of Talus's law waiting for three more to go through the kinematics and the
/// law's lane form together (as Talus's force loop takes its contacts four at a time): its
/// grains, its list entry and the grains' separation `x_i − x_j`.
#[derive(Clone, Copy, Default)]
struct Pending {
    i: usize,
    j: usize,
    k: usize,
    del: DVec3,
}

/// A touching pair's force on its first grain and both grains' torques, kept between the
/// three-pass kernel's force loop and its sums.
#[derive(Clone, Copy, Default)]
struct PairForce {
    force: DVec3,
    torque_i: DVec3,
    torque_j: DVec3,
}

/// Bits of a list entry's state under Talus's law.
const ALIVE: u8 = 1;
/// The contact carried a force at its last evaluation (`ContactForce::is_active`).
const ACTIVE: u8 = 2;

/// The chute's state as LAMMPS holds it: one array per quantity, grains in the order
/// Talus's snapshot holds them.
pub struct Kernel {
    /// Centre positions (wrapped into the box at each list build), velocities and spins.
    pub position: Vec<DVec3>,
    pub velocity: Vec<DVec3>,
    pub omega: Vec<DVec3>,
    force: Vec<DVec3>,
    torque: Vec<DVec3>,
    radius: Vec<f64>,
    mass: Vec<f64>,
    /// Half a time step over the mass, and over the moment of inertia (0 for a frozen
    /// grain): `fix nve/sphere`'s `dtfm` and `dtirotate`, taken once.
    half_step_over_mass: Vec<f64>,
    half_step_over_inertia: Vec<f64>,
    frozen: Vec<bool>,
    /// Periodic lengths along x and y.
    box_length: [f64; 2],
    gravity: DVec3,
    /// The half neighbour list: grain i's partners (all after i in memory) are
    /// `partner[first[i]..first[i + 1]]`, each pair with its tangential history.
    first: Vec<usize>,
    pub partner: Vec<u32>,
    shear: Vec<DVec3>,
    /// Positions at the list's build.
    built_at: Vec<DVec3>,
    /// The kernel's algorithm and law.
    pub variant: Variant,
    /// Talus's law: each entry's history and its `ALIVE` and `ACTIVE` bits.
    history: Vec<TalusHistory>,
    flags: Vec<u8>,
    params: LinearParams,
    inverse_mass: Vec<f64>,
    /// Grains in a cell (of the last list build) before their predecessor's in memory, as
    /// a fraction of all: how far the flow has carried the grains from the order of
    /// their cells, since the kernel never sorts them.
    pub out_of_order: f64,
    /// The three-pass kernel's touching pairs (first grain, list entry) and their forces.
    touching: Vec<(u32, u32)>,
    pair_forces: Vec<PairForce>,
    /// Seconds the three-pass kernel spent in its tests, its force loop and its sums.
    pub pass_seconds: [f64; 3],
    /// Contacts of Talus's law waiting for the lane form, and how many.
    pending: [Pending; 4],
    pending_len: usize,
    /// Neighbour-list builds so far.
    pub builds: u64,
    /// Candidate pairs tested so far, in the force loops of steps.
    pub tested: u64,
    /// The pruned kernel: each entry's sort key (its gap at the build, −∞ for a contact
    /// alive then), each block's partner blocks (`block_first`, `block_partners`), and the
    /// largest closing bound of each block's pairs since the build.
    gap: Vec<f64>,
    block_first: Vec<usize>,
    block_partners: Vec<u32>,
    block_threshold: Vec<f64>,
    /// Seconds spent in the list builds, the force loop (with gravity and the freeze)
    /// and the rest of the steps (kicks, drift, staleness checks).
    pub seconds: [f64; 3],
}

impl Kernel {
    /// The kernel `variant` from the state Talus's snapshot `s` holds after its priming
    /// pass (step 0), in a box periodic along x and y of `box_length`, under `gravity`.
    pub fn from_snapshot(
        s: &GrainSnapshot,
        box_length: [f64; 2],
        gravity: DVec3,
        variant: Variant,
    ) -> Self {
        let n = s.len();
        let radius: Vec<f64> = (0..n).map(|i| s.radius(i)).collect();
        // Density 1 (the data file's); a frozen grain's inverse mass is 0 in the snapshot.
        let mass: Vec<f64> = radius
            .iter()
            .map(|r| 4.0 / 3.0 * std::f64::consts::PI * r * r * r)
            .collect();
        let frozen: Vec<bool> = (0..n).map(|i| s.inverse_mass(i) == 0.0).collect();
        for i in 0..n {
            if !frozen[i] {
                let m = 1.0 / s.inverse_mass(i);
                assert!((m - mass[i]).abs() <= 1e-12 * m, "grain {i}: density 1");
            }
        }
        let half = 0.5 * TIME_STEP;
        let half_step_over_mass = (0..n)
            .map(|i| if frozen[i] { 0.0 } else { half / mass[i] })
            .collect();
        let half_step_over_inertia = (0..n)
            .map(|i| {
                let r = radius[i];
                if frozen[i] {
                    0.0
                } else {
                    half / (INERTIA * r * r * mass[i])
                }
            })
            .collect();
        let mut kernel = Self {
            half_step_over_mass,
            half_step_over_inertia,
            position: (0..n).map(|i| s.position(i)).collect(),
            velocity: (0..n).map(|i| s.velocity(i)).collect(),
            omega: s.omega[..n].to_vec(),
            force: vec![DVec3::ZERO; n],
            torque: vec![DVec3::ZERO; n],
            radius,
            mass,
            frozen,
            box_length,
            gravity,
            first: Vec::new(),
            partner: Vec::new(),
            shear: Vec::new(),
            built_at: Vec::new(),
            variant,
            history: Vec::new(),
            flags: Vec::new(),
            params: LinearParams {
                normal_stiffness: NORMAL_STIFFNESS,
                normal_damping: NormalDamping::Rate(NORMAL_DAMPING),
                tangential_stiffness: TANGENTIAL_STIFFNESS,
                tangential_damping_ratio: 0.0,
                friction: FRICTION,
            },
            inverse_mass: (0..n).map(|i| s.inverse_mass(i)).collect(),
            out_of_order: 0.0,
            touching: Vec::new(),
            pair_forces: Vec::new(),
            pass_seconds: [0.0; 3],
            pending: [Pending::default(); 4],
            pending_len: 0,
            builds: 0,
            tested: 0,
            gap: Vec::new(),
            block_first: Vec::new(),
            block_partners: Vec::new(),
            block_threshold: Vec::new(),
            seconds: [0.0; 3],
        };
        kernel.build_list();
        // LAMMPS's setup computes the first forces without advancing the histories.
        kernel.forces(false);
        kernel
    }

    /// `x_i − x_j` by the nearest image along x and y (LAMMPS's ghost grains need none),
    /// without branches: a compare and a select per axis, as Talus's lanes take it (the
    /// force loop took 62 ns a grain-step against 73 with a branch per axis).
    #[inline(always)]
    fn separation(&self, i: usize, j: usize) -> DVec3 {
        let mut d = self.position[i] - self.position[j];
        for (k, &length) in self.box_length.iter().enumerate() {
            let half = 0.5 * length;
            let up = if d[k] > half { length } else { 0.0 };
            let down = if d[k] < -half { length } else { 0.0 };
            d[k] = d[k] - up + down;
        }
        d
    }

    /// Bins the grains in cells at least one neighbour cut-off wide and keeps every pair
    /// within it, each under its first grain in memory, frozen pairs excluded
    /// (`neigh_modify exclude group bottom bottom`); carries each kept pair's tangential
    /// history over from the old list.
    fn build_list(&mut self) {
        let n = self.position.len();
        for p in &mut self.position {
            for (k, &length) in self.box_length.iter().enumerate() {
                p[k] = p[k].rem_euclid(length);
            }
        }
        let max_radius = self.radius.iter().copied().fold(0.0, f64::max);
        let cut = 2.0 * max_radius + SKIN;
        let (z_min, z_max) = self
            .position
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.z), hi.max(p.z))
            });
        let cells_along = |length: f64| ((length / cut).floor() as usize).max(1);
        let (nx, ny) = (
            cells_along(self.box_length[0]),
            cells_along(self.box_length[1]),
        );
        let nz = cells_along(z_max - z_min + 1e-9);
        let cell_edge = [
            self.box_length[0] / nx as f64,
            self.box_length[1] / ny as f64,
            (z_max - z_min + 1e-9) / nz as f64,
        ];
        let cell_of = |p: DVec3| {
            let cx = ((p.x / cell_edge[0]) as usize).min(nx - 1);
            let cy = ((p.y / cell_edge[1]) as usize).min(ny - 1);
            let cz = (((p.z - z_min) / cell_edge[2]) as usize).min(nz - 1);
            [cx, cy, cz]
        };
        let index = |c: [usize; 3]| (c[2] * ny + c[1]) * nx + c[0];
        // A counting sort of the grains by cell.
        let mut start = vec![0usize; nx * ny * nz + 1];
        let cells: Vec<[usize; 3]> = self.position.iter().map(|&p| cell_of(p)).collect();
        self.out_of_order = cells
            .windows(2)
            .filter(|pair| index(pair[1]) < index(pair[0]))
            .count() as f64
            / n.max(1) as f64;
        for c in &cells {
            start[index(*c) + 1] += 1;
        }
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let mut fill = start.clone();
        let mut sorted = vec![0u32; n];
        for (i, c) in cells.iter().enumerate() {
            sorted[fill[index(*c)]] = i as u32;
            fill[index(*c)] += 1;
        }
        let wrap = |c: usize, d: isize, cells: usize| (c as isize + d).rem_euclid(cells as isize);
        // Each cell's neighbouring cells, each once (a periodic axis may have fewer than
        // three cells), listed once per build.
        let mut around: Vec<[u32; 27]> = Vec::with_capacity(nx * ny * nz);
        let mut around_len: Vec<u8> = Vec::with_capacity(nx * ny * nz);
        for cz in 0..nz {
            for cy in 0..ny {
                for cx in 0..nx {
                    let mut cells = [0u32; 27];
                    let mut len = 0;
                    for dz in -1isize..=1 {
                        let z = cz as isize + dz;
                        if z < 0 || z >= nz as isize {
                            continue;
                        }
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                let c = index([
                                    wrap(cx, dx, nx) as usize,
                                    wrap(cy, dy, ny) as usize,
                                    z as usize,
                                ]) as u32;
                                if !cells[..len].contains(&c) {
                                    cells[len] = c;
                                    len += 1;
                                }
                            }
                        }
                    }
                    around.push(cells);
                    around_len.push(len as u8);
                }
            }
        }
        let mut first = Vec::with_capacity(n + 1);
        let mut partner = Vec::with_capacity(self.partner.len());
        let mut shear = Vec::with_capacity(self.shear.len());
        let mut history = Vec::with_capacity(self.history.len());
        let mut flags = Vec::with_capacity(self.flags.len());
        let talus_law = self.variant.talus_law();
        let pruned = self.variant == Variant::TalusLawPruned;
        let mut gap = Vec::with_capacity(self.gap.len());
        let mut neighbours: Vec<u32> = Vec::new();
        let mut keyed: Vec<(f64, u32, Option<usize>)> = Vec::new();
        for (i, &cell) in cells.iter().enumerate() {
            first.push(partner.len());
            neighbours.clear();
            let home = index(cell);
            for &c in &around[home][..around_len[home] as usize] {
                let c = c as usize;
                for &j in &sorted[start[c]..start[c + 1]] {
                    let ju = j as usize;
                    if ju <= i || (self.frozen[i] && self.frozen[ju]) {
                        continue;
                    }
                    let reach = self.radius[i] + self.radius[ju] + SKIN;
                    if self.separation(i, ju).length_squared() < reach * reach {
                        neighbours.push(j);
                    }
                }
            }
            // In memory order, as a sorted packing's lists come out of LAMMPS's bins (the
            // pruned kernel's in order of gap, live contacts first).
            neighbours.sort_unstable();
            let old = if self.first.is_empty() {
                &[][..]
            } else {
                &self.partner[self.first[i]..self.first[i + 1]]
            };
            let old_start = self.first.get(i).copied().unwrap_or(0);
            keyed.clear();
            for &j in &neighbours {
                let found = old.iter().position(|&o| o == j).map(|k| old_start + k);
                // Only the pruned kernel reads the key (a square root a candidate).
                let alive = talus_law && found.is_some_and(|k| self.flags[k] & ALIVE != 0);
                let key = if !pruned {
                    0.0
                } else if alive {
                    f64::NEG_INFINITY
                } else {
                    self.separation(i, j as usize).length()
                        - self.radius[i]
                        - self.radius[j as usize]
                };
                keyed.push((key, j, found));
            }
            if pruned {
                keyed.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            }
            for &(key, j, found) in &keyed {
                partner.push(j);
                if pruned {
                    gap.push(key);
                }
                if talus_law {
                    history.push(found.map_or(TalusHistory::default(), |k| self.history[k]));
                    flags.push(found.map_or(0, |k| self.flags[k]));
                } else {
                    shear.push(found.map_or(DVec3::ZERO, |k| self.shear[k]));
                }
            }
        }
        first.push(partner.len());
        self.first = first;
        self.partner = partner;
        self.shear = shear;
        self.history = history;
        self.flags = flags;
        self.gap = gap;
        self.built_at = self.position.clone();
        self.builds += 1;
        // Each block's partner blocks (its own among them), for the pruned kernel's bounds.
        let blocks = n.div_ceil(BLOCK_GRAINS);
        self.block_first.clear();
        self.block_partners.clear();
        for b in 0..blocks {
            self.block_first.push(self.block_partners.len());
            let start = self.block_partners.len();
            self.block_partners.push(b as u32);
            let grains = b * BLOCK_GRAINS..((b + 1) * BLOCK_GRAINS).min(n);
            for &j in &self.partner[self.first[grains.start]..self.first[grains.end]] {
                let pb = j / BLOCK_GRAINS as u32;
                if !self.block_partners[start..].contains(&pb) {
                    self.block_partners.push(pb);
                }
            }
        }
        self.block_first.push(self.block_partners.len());
        self.block_threshold = vec![0.0; blocks];
    }

    /// Whether the list is stale: LAMMPS's test, any grain moved more than half the skin
    /// since the build; the others', Talus's bound D on every grain's move about
    /// the moves' common part (the smaller of the largest move and the half diagonal of
    /// the box bounding all moves) beyond half the skin (`architecture.md` §6).
    fn list_stale(&mut self) -> bool {
        if self.variant == Variant::Plain {
            let limit = 0.25 * SKIN * SKIN;
            return self
                .position
                .iter()
                .zip(&self.built_at)
                .any(|(p, b)| (*p - *b).length_squared() > limit);
        }
        if self.variant == Variant::TalusLawPruned {
            return self.block_bounds();
        }
        let (mut largest, mut low, mut high) = (0.0f64, DVec3::INFINITY, DVec3::NEG_INFINITY);
        for (p, b) in self.position.iter().zip(&self.built_at) {
            let moved = *p - *b;
            largest = largest.max(moved.length_squared());
            low = low.min(moved);
            high = high.max(moved);
        }
        largest.sqrt().min(0.5 * (high - low).length()) > 0.5 * SKIN
    }

    /// The pruned kernel's staleness test (as the refined kernel's) and its blocks' closing
    /// bounds: for grains of blocks a and b, |Δ_i − Δ_j| is at most the smaller of their
    /// largest moves' sum and their moves' half diagonals' sum plus the distance between
    /// the centres of the boxes bounding them.
    fn block_bounds(&mut self) -> bool {
        let n = self.position.len();
        let blocks = n.div_ceil(BLOCK_GRAINS);
        // Per block: the largest move, the centre and half diagonal of the moves' box.
        let mut moves: Vec<(f64, DVec3, f64)> = Vec::with_capacity(blocks);
        let (mut largest, mut low, mut high) = (0.0f64, DVec3::INFINITY, DVec3::NEG_INFINITY);
        for b in 0..blocks {
            let grains = b * BLOCK_GRAINS..((b + 1) * BLOCK_GRAINS).min(n);
            let (mut l2, mut lo, mut hi) = (0.0f64, DVec3::INFINITY, DVec3::NEG_INFINITY);
            for i in grains {
                let moved = self.position[i] - self.built_at[i];
                l2 = l2.max(moved.length_squared());
                lo = lo.min(moved);
                hi = hi.max(moved);
            }
            largest = largest.max(l2);
            low = low.min(lo);
            high = high.max(hi);
            moves.push((l2.sqrt(), 0.5 * (lo + hi), 0.5 * (hi - lo).length()));
        }
        for a in 0..blocks {
            let (ma, ua, sa) = moves[a];
            let mut bound = 0.0f64;
            for &b in &self.block_partners[self.block_first[a]..self.block_first[a + 1]] {
                let (mb, ub, sb) = moves[b as usize];
                bound = bound.max((ma + mb).min(sa + sb + (ua - ub).length()));
            }
            self.block_threshold[a] = self.block_threshold[a].max(bound);
        }
        largest.sqrt().min(0.5 * (high - low).length()) > 0.5 * SKIN
    }

    /// `pair gran/hooke/history` (`newton on`), then gravity and the frozen grains' forces
    /// cleared (`fix gravity`, `fix freeze`). `advance`: whether the tangential histories
    /// take the step (not in LAMMPS's setup, its `shearupdate`).
    fn forces(&mut self, advance: bool) {
        self.force.fill(DVec3::ZERO);
        self.torque.fill(DVec3::ZERO);
        if self.variant == Variant::Passes {
            self.forces_in_passes(advance);
        } else {
            self.forces_in_one_pass(advance);
        }
        for i in 0..self.position.len() {
            if self.frozen[i] {
                self.force[i] = DVec3::ZERO;
                self.torque[i] = DVec3::ZERO;
            } else {
                self.force[i] += self.mass[i] * self.gravity;
            }
        }
    }

    /// The pair loop of LAMMPS's shape: each candidate tested, and a touching pair's force
    /// added to both grains' totals, in one pass over the list.
    fn forces_in_one_pass(&mut self, advance: bool) {
        let n = self.position.len();
        let pruned = self.variant == Variant::TalusLawPruned;
        for i in 0..n {
            let radi = self.radius[i];
            let (start, mut end) = (self.first[i], self.first[i + 1]);
            if pruned {
                // A pair can touch only if its gap at the build is within its blocks'
                // bound; a contact alive at the build (key −∞) is always within.
                let reach = self.block_threshold[i / BLOCK_GRAINS];
                end = start
                    + self.gap[start..end]
                        .iter()
                        .take_while(|&&g| g <= reach)
                        .count();
            }
            self.tested += (end - start) as u64;
            for k in start..end {
                let j = self.partner[k] as usize;
                let del = self.separation(i, j);
                let rsq = del.length_squared();
                let radsum = radi + self.radius[j];
                let touching = rsq < radsum * radsum;
                if self.variant.talus_law() {
                    // Made on touching; kept while touching, and for one evaluation after
                    // the bodies part if it carried a force (Talus's narrow phase).
                    if touching || self.flags[k] == ALIVE | ACTIVE {
                        self.talus_pair(i, j, k, del, advance);
                    } else {
                        self.flags[k] = 0;
                    }
                } else if touching {
                    self.pair(i, j, k, del, rsq, advance);
                } else {
                    self.shear[k] = DVec3::ZERO;
                }
            }
        }
        if self.pending_len > 0 {
            self.flush_talus(advance);
        }
    }

    /// The force between touching grains `i` and `j`, pair `k` of the list, separated by
    /// `del` (`x_i − x_j`, `rsq` its square): `gran/hooke/history`'s loop body.
    #[inline(always)]
    fn pair(&mut self, i: usize, j: usize, k: usize, del: DVec3, rsq: f64, advance: bool) {
        let p = self.pair_force(i, j, k, del, rsq, advance);
        self.force[i] += p.force;
        self.torque[i] += p.torque_i;
        self.force[j] -= p.force;
        self.torque[j] += p.torque_j;
    }

    /// The three-pass kernel's forces: the overlap tests (a touching pair listed, a parted
    /// one's history cleared), the force loop over the touching pairs into their records,
    /// and the sums of the records onto the grains, each a pass of its own.
    fn forces_in_passes(&mut self, advance: bool) {
        let n = self.position.len();
        let began = Instant::now();
        self.touching.clear();
        for i in 0..n {
            let radi = self.radius[i];
            let (start, end) = (self.first[i], self.first[i + 1]);
            self.tested += (end - start) as u64;
            for k in start..end {
                let j = self.partner[k] as usize;
                let radsum = radi + self.radius[j];
                if self.separation(i, j).length_squared() < radsum * radsum {
                    self.touching.push((i as u32, k as u32));
                } else {
                    self.shear[k] = DVec3::ZERO;
                }
            }
        }
        let tested = Instant::now();
        let mut pair_forces = std::mem::take(&mut self.pair_forces);
        pair_forces.clear();
        for c in 0..self.touching.len() {
            let (i, k) = self.touching[c];
            let (i, k) = (i as usize, k as usize);
            let j = self.partner[k] as usize;
            let del = self.separation(i, j);
            pair_forces.push(self.pair_force(i, j, k, del, del.length_squared(), advance));
        }
        let forced = Instant::now();
        for (&(i, k), p) in self.touching.iter().zip(&pair_forces) {
            let (i, j) = (i as usize, self.partner[k as usize] as usize);
            self.force[i] += p.force;
            self.torque[i] += p.torque_i;
            self.force[j] -= p.force;
            self.torque[j] += p.torque_j;
        }
        self.pair_forces = pair_forces;
        let end = Instant::now();
        for (total, (from, to)) in
            self.pass_seconds
                .iter_mut()
                .zip([(began, tested), (tested, forced), (forced, end)])
        {
            *total += (to - from).as_secs_f64();
        }
    }

    /// `gran/hooke/history`'s force between touching grains `i` and `j` (pair `k`,
    /// separated by `del`, `rsq` its square), their history advanced: the force on `i` and
    /// the torques on both (a torque `t` added as `+(−r t)`, the bits of LAMMPS's `−= r t`).
    #[inline(always)]
    fn pair_force(
        &mut self,
        i: usize,
        j: usize,
        k: usize,
        del: DVec3,
        rsq: f64,
        advance: bool,
    ) -> PairForce {
        let (radi, radj) = (self.radius[i], self.radius[j]);
        let radsum = radi + radj;
        let r = rsq.sqrt();
        let rinv = 1.0 / r;
        let rsqinv = 1.0 / rsq;
        // Relative translational velocity, its normal and tangential parts.
        let vr = self.velocity[i] - self.velocity[j];
        let vnnr = vr.dot(del);
        let vn = del * (vnnr * rsqinv);
        let vt = vr - vn;
        // Relative rotational velocity.
        let wr = (radi * self.omega[i] + radj * self.omega[j]) * rinv;
        let (mi, mj) = (self.mass[i], self.mass[j]);
        let meff = if self.frozen[j] {
            mi
        } else if self.frozen[i] {
            mj
        } else {
            mi * mj / (mi + mj)
        };
        // Normal force: Hookean contact and normal velocity damping.
        let damp = meff * NORMAL_DAMPING * vnnr * rsqinv;
        let ccel = NORMAL_STIFFNESS * (radsum - r) * rinv - damp;
        // Relative tangential velocity at the contact (no tangential damping: `dampflag 0`).
        let vtr = DVec3::new(
            vt.x - (del.z * wr.y - del.y * wr.z),
            vt.y - (del.x * wr.z - del.z * wr.x),
            vt.z - (del.y * wr.x - del.x * wr.y),
        );
        // Shear history: the step's increment, then the projection onto the new tangent
        // plane.
        let mut shear = self.shear[k];
        if advance {
            shear += vtr * TIME_STEP;
        }
        let shrmag = shear.length();
        let rsht = shear.dot(del) * rsqinv;
        if advance {
            shear -= del * rsht;
        }
        let mut fs = -TANGENTIAL_STIFFNESS * shear;
        // Coulomb's limit.
        let fs_mag = fs.length();
        let fn_mag = FRICTION * (ccel * r).abs();
        if fs_mag > fn_mag {
            if shrmag != 0.0 {
                shear *= fn_mag / fs_mag;
                fs *= fn_mag / fs_mag;
            } else {
                fs = DVec3::ZERO;
            }
        }
        self.shear[k] = shear;
        let f = del * ccel + fs;
        let tor = rinv
            * DVec3::new(
                del.y * fs.z - del.z * fs.y,
                del.z * fs.x - del.x * fs.z,
                del.x * fs.y - del.y * fs.x,
            );
        PairForce {
            force: f,
            torque_i: -(radi * tor),
            torque_j: -(radj * tor),
        }
    }

    /// Queues Talus's linear law between grains `i` and `j` (entry `k`, separated by
    /// `del`) for the lanes of `flush_talus`.
    #[inline(always)]
    fn talus_pair(&mut self, i: usize, j: usize, k: usize, del: DVec3, advance: bool) {
        self.pending[self.pending_len] = Pending { i, j, k, del };
        self.pending_len += 1;
        if self.pending_len == 4 {
            self.flush_talus(advance);
        }
    }

    /// Evaluates the queued contacts of Talus's law, four lanes at a time (fewer at the
    /// loop's end, the empty lanes repeating the first): their kinematics as
    /// `ContactKinematics::grain_grain` forms them, gathered from the kernel's arrays; the
    /// law's lane form without energies (Talus's force loop at an unobserved step); then
    /// their histories and flags, and the forces and torques as Talus's force loop and sums
    /// apply them. Not `advance`: the evaluation of Talus's priming pass (a time step of 0).
    /// The kinematics are written out again on purpose, from the kernel's own arrays:
    /// `tests/reference_chute.rs` holds Talus to this kernel, which shares with it only the
    /// law and `ContactKinematicsLanes::set_displacement`.
    fn flush_talus(&mut self, advance: bool) {
        let dt = if advance { TIME_STEP } else { 0.0 };
        let n = std::mem::take(&mut self.pending_len);
        let pending: [Pending; 4] = std::array::from_fn(|l| self.pending[l.min(n - 1)]);
        // A contact's first evaluation starts from a default history.
        for p in &pending[..n] {
            if self.flags[p.k] & ALIVE == 0 {
                self.history[p.k] = TalusHistory::default();
            }
        }
        let (i, j) = (pending.map(|p| p.i), pending.map(|p| p.j));
        let lanes_of = |v: &[DVec3], g: [usize; 4]| V4::from_fn(|l| v[g[l]]);
        let scalars_of = |v: &[f64], g: [usize; 4]| F4::from_fn(|l| v[g[l]]);
        let (ra, rb) = (scalars_of(&self.radius, i), scalars_of(&self.radius, j));
        let d = V4::from_fn(|l| pending[l].del);
        let dist = d.length();
        let zero = F4::zero();
        let normal = dist
            .gt(zero)
            .select3(d * (F4::splat(1.0) / dist), V4::splat(DVec3::Z));
        let overlap = ra + rb - dist;
        let half = F4::splat(0.5);
        let branch_a = -normal * (ra - half * overlap);
        let branch_b = normal * (rb - half * overlap);
        let (wa, wb) = (lanes_of(&self.omega, i), lanes_of(&self.omega, j));
        let (va, vb) = (lanes_of(&self.velocity, i), lanes_of(&self.velocity, j));
        let relative_velocity = (va + wa.cross(branch_a)) - (vb + V4::zero() + wb.cross(branch_b));
        let normal_velocity = relative_velocity.dot(normal);
        let inverse_mass = (
            scalars_of(&self.inverse_mass, i),
            scalars_of(&self.inverse_mass, j),
        );
        let mut kin = ContactKinematicsLanes {
            normal,
            overlap,
            point: lanes_of(&self.position, i) + branch_a,
            branch_a,
            branch_b,
            relative_velocity,
            normal_velocity,
            tangential_velocity: relative_velocity - normal * normal_velocity,
            displacement: V4::zero(),
            previous_overlap: zero,
            previous_normal: V4::zero(),
            relative_omega: wa - wb,
            effective_mass: F4::splat(1.0) / (inverse_mass.0 + inverse_mass.1),
            effective_radius: ra * rb / (ra + rb),
            min_radius: rb.lt(ra).select(rb, ra),
        };
        let previous = pending.map(|p| self.history[p.k]);
        kin.set_displacement(
            V4::from_fn(|l| previous[l].normal),
            F4::from_fn(|l| previous[l].overlap),
            SpinLanes { a: wa, b: wb },
            dt,
        );
        // The padding lanes work on copies; the queued ones on their entries' springs.
        let mut springs = previous.map(|h| h.spring);
        let params = [&self.params; 4];
        let lanes = (1u32 << n) - 1;
        let (_, r) =
            LinearSpring::evaluate_lanes(params, &kin, springs.each_mut(), lanes, dt, false);
        let force = r.force.to_array();
        let torque_a = (kin.branch_a.cross(r.force) + r.torque_a).to_array();
        let torque_b = (kin.branch_b.cross(-r.force) + r.torque_b).to_array();
        let (normal, overlap) = (kin.normal.to_array(), kin.overlap.to_array());
        for l in 0..n {
            let p = pending[l];
            self.history[p.k] = TalusHistory {
                spring: springs[l],
                normal: normal[l],
                overlap: overlap[l],
            };
            let active = overlap[l] > 0.0 || force[l] != DVec3::ZERO;
            self.flags[p.k] = ALIVE | if active { ACTIVE } else { 0 };
            self.force[p.i] += force[l];
            self.force[p.j] -= force[l];
            self.torque[p.i] += torque_a[l];
            self.torque[p.j] += torque_b[l];
        }
    }

    /// `fix nve/sphere`'s half kick of the moving grains' velocities and spins.
    fn kick(&mut self) {
        // A frozen grain's factors are 0 and its force and torque are cleared: no branch.
        for i in 0..self.position.len() {
            self.velocity[i] += self.half_step_over_mass[i] * self.force[i];
            self.omega[i] += self.half_step_over_inertia[i] * self.torque[i];
        }
    }

    /// One velocity-Verlet step: kick, drift, the list rebuilt if stale, forces, kick.
    pub fn step(&mut self) {
        let start = Instant::now();
        self.kick();
        for i in 0..self.position.len() {
            if !self.frozen[i] {
                self.position[i] += TIME_STEP * self.velocity[i];
            }
        }
        let stale = self.list_stale();
        let drifted = Instant::now();
        if stale {
            self.build_list();
        }
        let built = Instant::now();
        self.forces(true);
        let forced = Instant::now();
        self.kick();
        let end = Instant::now();
        self.seconds[0] += (built - drifted).as_secs_f64();
        self.seconds[1] += (forced - built).as_secs_f64();
        self.seconds[2] += (drifted - start).as_secs_f64() + (end - forced).as_secs_f64();
    }

    /// Contacts of Talus's law that carried a force at their last evaluation: the count
    /// Talus reports (`ContactForce::is_active`). None for LAMMPS's law.
    pub fn active_contacts(&self) -> Option<usize> {
        self.variant
            .talus_law()
            .then(|| self.flags.iter().filter(|&&f| f & ACTIVE != 0).count())
    }

    /// Σ½mv² and Σ½Iω² over every grain, as LAMMPS's `ke` and `erotate/sphere`.
    pub fn energies(&self) -> (f64, f64) {
        let mut translational = 0.0;
        let mut rotational = 0.0;
        for i in 0..self.position.len() {
            let m = self.mass[i];
            let r = self.radius[i];
            translational += 0.5 * m * self.velocity[i].length_squared();
            rotational += 0.5 * INERTIA * m * r * r * self.omega[i].length_squared();
        }
        (translational, rotational)
    }
}
