//! The RON schema of a scene file. Every field is documented in
//! `docs/scene-reference.md`; units are SI.

use std::fmt;

use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};

/// A vector written as a tuple `(x, y, z)`.
pub type Vec3 = [f64; 3];

fn default_dimension() -> u8 {
    3
}
fn default_steps_per_collision() -> f64 {
    50.0
}
fn default_overlap_tolerance() -> f64 {
    1e-3
}

/// A whole scene.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "Scene")]
pub struct SceneFile {
    /// Name of the experiment; default output folder is `out/<name>/`.
    pub name: String,
    /// 2 (disks in the xy-plane) or 3 (spheres). Default: 3.
    #[serde(default = "default_dimension")]
    pub dimension: u8,
    /// Gravitational acceleration, m/s². Default: (0, 0, 0).
    #[serde(default)]
    pub gravity: Vec3,
    /// Simulated duration, s. Give this or `steps`.
    #[serde(default)]
    pub duration: Option<f64>,
    /// Number of steps. Give this or `duration`.
    #[serde(default)]
    pub steps: Option<u64>,
    /// Time step, s. Default: automatic, the shortest contact time / `steps_per_collision`.
    #[serde(default)]
    pub time_step: Option<f64>,
    /// Steps per shortest contact for the automatic time step. Default: 50.
    #[serde(default = "default_steps_per_collision")]
    pub steps_per_collision: f64,
    /// Accept a `time_step` above the stability bound. Default: false.
    #[serde(default)]
    pub force_time_step: bool,
    /// Integration scheme. Default: VelocityVerlet.
    #[serde(default)]
    pub integrator: IntegratorName,
    /// Whether grain rotation is integrated. Default: automatic, on exactly when a
    /// contact law of the scene can torque a grain. `false` with such a law is an error.
    #[serde(default)]
    pub rotation: Option<bool>,
    /// Plugins (contact laws) the scene uses, by name.
    #[serde(default)]
    pub plugins: Vec<String>,
    /// Materials.
    pub materials: Vec<MaterialSpec>,
    /// Contact laws of unlike material pairs, overriding the mixing rule.
    #[serde(default)]
    pub pairs: Vec<PairSpec>,
    /// Walls.
    #[serde(default)]
    pub walls: Vec<WallSpec>,
    /// Grain sources. Default: none (a scene with `start_from` may add no grain).
    #[serde(default)]
    pub grains: Vec<GrainSource>,
    /// A saved state (`state.ron` of an earlier run, relative to this file) whose grains
    /// and contacts, with their histories, the scene starts from, before the grains of
    /// `grains`. Default: none.
    #[serde(default)]
    pub start_from: Option<String>,
    /// Largest initial overlap allowed, as a fraction of the smaller radius. Default: 1e-3.
    #[serde(default = "default_overlap_tolerance")]
    pub initial_overlap_tolerance: f64,
    /// Stop early once the mean kinetic energy per grain falls below this, J.
    #[serde(default)]
    pub settle_kinetic_energy: Option<f64>,
    /// Re-sort the grains in memory by position (rows of cells one largest diameter wide)
    /// before the first step and then every this many steps, as LAMMPS's `atom_modify
    /// sort` does: grains a pour or a mixer carries far from where they started keep
    /// their neighbours near in memory. No physics changes (the order of the force sums,
    /// and so the last bits, may). Default: none (a `LammpsData` source is sorted as it is
    /// read; grains keep the order they were made in).
    #[serde(default)]
    pub sort_grains_every: Option<u64>,
    /// What to write.
    #[serde(default)]
    pub output: OutputSpec,
    /// Stress sampling over the domain and regions. Default: none (no stress system).
    #[serde(default)]
    pub sampling: Option<SamplingSpec>,
    /// Periodic boundaries: the axes that wrap around and their extent. Default: none.
    #[serde(default)]
    pub periodic: Option<PeriodicSpec>,
    /// Packing by sequential deposition: batches of grains dropped into the container,
    /// each once the last has settled. Default: none.
    #[serde(default)]
    pub deposition: Option<DepositionSpec>,
    /// Packing by isotropic compression of the periodic cell. Default: none.
    #[serde(default)]
    pub compression: Option<CompressionSpec>,
}

/// Sequential deposition: `deposition: (material: "glass", region: (...), radius:
/// Uniform(min: .., max: ..), batch_size: 200, batches: 5, settle_kinetic_energy: 1e-9,
/// unbalanced_force: 1e-2)`. A batch is inserted (random sequential insertion in
/// `region`, clear of every grain) at the start and whenever the grains have settled:
/// mean kinetic energy per grain and unbalanced-force ratio both below their thresholds.
/// The run stops once the last batch has settled.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepositionSpec {
    /// Material of the deposited grains.
    pub material: String,
    /// Insertion region (above the container), m.
    pub region: Region,
    /// Radius distribution.
    pub radius: RadiusSpec,
    /// Grains per batch.
    pub batch_size: usize,
    /// Number of batches.
    pub batches: usize,
    /// Random seed (batch k uses seed + k). Default: 0.
    #[serde(default)]
    pub seed: u64,
    /// Settled when the mean kinetic energy per grain is below this, J.
    pub settle_kinetic_energy: f64,
    /// ... and the unbalanced-force ratio is below this.
    pub unbalanced_force: f64,
    /// Simulated time between settling checks, s. Default: `output.report_interval`.
    #[serde(default)]
    pub check_interval: Option<f64>,
}

/// Isotropic compression of a periodic cell: `compression: (target_solid_fraction: 0.62,
/// max_strain_rate: 10.0, max_inertial_number: 1e-3, unbalanced_force: 1e-4)`. The cell
/// shrinks homothetically (grain centres scaled with it) at the largest strain rate that
/// keeps the inertial number I = ε̇ d̄ √(ρ/p) below the bound, until the target is met;
/// then it holds and the run stops once the unbalanced-force ratio is below its bound.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompressionSpec {
    /// Target solid fraction (grain volume / cell volume; 2-D: areas). Give this or
    /// `target_pressure`.
    #[serde(default)]
    pub target_solid_fraction: Option<f64>,
    /// Target mean pressure p = −tr σ / D from the contact (Love–Weber) stress, Pa.
    #[serde(default)]
    pub target_pressure: Option<f64>,
    /// Largest strain rate, 1/s (used while the pressure is too low to bound it).
    pub max_strain_rate: f64,
    /// Bound on the inertial number. Default: 1e-3 (quasi-static).
    #[serde(default = "default_max_inertial_number")]
    pub max_inertial_number: f64,
    /// Stop once the target is met and the unbalanced-force ratio is below this.
    /// Default: 1e-4.
    #[serde(default = "default_unbalanced_force")]
    pub unbalanced_force: f64,
    /// Relative tolerance on the target pressure. Default: 0.01.
    #[serde(default = "default_pressure_tolerance")]
    pub pressure_tolerance: f64,
}

fn default_max_inertial_number() -> f64 {
    1e-3
}

fn default_unbalanced_force() -> f64 {
    1e-4
}

fn default_pressure_tolerance() -> f64 {
    0.01
}

/// Integration scheme names.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
pub enum IntegratorName {
    /// Velocity Verlet.
    #[default]
    VelocityVerlet,
    /// Symplectic Euler.
    SymplecticEuler,
    /// Gear predictor–corrector (six values for positions, four for spins).
    Gear,
}

/// A material.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Name grains and walls refer to.
    pub name: String,
    /// Density, kg/m³ (2-D: per metre of thickness).
    pub density: f64,
    /// Contact law and its parameters for contacts with this material.
    #[serde(default)]
    pub contact: Option<ContactSpec>,
}

/// A contact law by name, with its parameters: `(law: "linear_spring", stiffness: 1e5, ...)`,
/// and optional rolling and twisting parts: `rolling: "constant_torque"`.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSpec {
    /// Law name.
    pub law: String,
    /// Rolling-resistance part, by name.
    pub rolling: Option<String>,
    /// Twisting-resistance part, by name.
    pub twisting: Option<String>,
    /// Numeric parameters in file order.
    pub params: Vec<(String, f64)>,
}

impl ContactSpec {
    /// The law with its parts, as `talus check` and error messages show it.
    pub fn label(&self) -> String {
        let mut out = self.law.clone();
        if let Some(r) = &self.rolling {
            out.push_str(&format!(" + rolling `{r}`"));
        }
        if let Some(t) = &self.twisting {
            out.push_str(&format!(" + twisting `{t}`"));
        }
        out
    }
}

impl<'de> Deserialize<'de> for ContactSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = ContactSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a contact law: (law: \"name\", rolling: \"part\", twisting: \"part\", parameter: number, ...)",
                )
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<ContactSpec, A::Error> {
                let mut law = None;
                let mut rolling = None;
                let mut twisting = None;
                let mut params = Vec::new();
                while let Some(key) = map.next_key::<String>()? {
                    if key == "law" {
                        law = Some(map.next_value::<String>()?);
                    } else if key == "rolling" {
                        rolling = Some(map.next_value::<String>()?);
                    } else if key == "twisting" {
                        twisting = Some(map.next_value::<String>()?);
                    } else {
                        let v = map.next_value::<f64>()?;
                        if params.iter().any(|(k, _)| *k == key) {
                            return Err(de::Error::custom(format!(
                                "parameter `{key}` given twice"
                            )));
                        }
                        params.push((key, v));
                    }
                }
                let law = law.ok_or_else(|| de::Error::missing_field("law"))?;
                Ok(ContactSpec {
                    law,
                    rolling,
                    twisting,
                    params,
                })
            }
        }
        d.deserialize_struct("Contact", &["law"], V)
    }
}

/// A contact law for one unlike pair.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairSpec {
    /// The two material names.
    pub materials: (String, String),
    /// The law and its parameters for this pair.
    pub contact: ContactSpec,
}

/// A wall or a set of walls.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum WallSpec {
    /// An infinite plane.
    Plane {
        /// Name in reports.
        name: String,
        /// A point on the plane, m.
        point: Vec3,
        /// Normal pointing towards the grains.
        normal: Vec3,
        /// Material name.
        material: String,
        /// Prescribed velocity, m/s. Default: (0, 0, 0).
        #[serde(default)]
        velocity: Vec3,
        /// Hold a pressure instead of a velocity. Default: none.
        #[serde(default)]
        servo: Option<ServoSpec>,
        /// Move at a set strain rate against an opposite wall instead of a velocity.
        /// Default: none.
        #[serde(default)]
        strain_rate: Option<StrainRateSpec>,
    },
    /// The inner faces of an axis-aligned box: 6 planes (4 in 2-D).
    Box {
        /// Lower corner, m.
        min: Vec3,
        /// Upper corner, m.
        max: Vec3,
        /// Material name.
        material: String,
        /// Faces to leave out, among "x_min", "x_max", "y_min", "y_max", "z_min", "z_max".
        #[serde(default)]
        omit: Vec<String>,
    },
}

/// A radius distribution.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum RadiusSpec {
    /// Every grain has this radius, m.
    Fixed(f64),
    /// Radii uniform in [min, max], m.
    Uniform {
        /// Smallest radius.
        min: f64,
        /// Largest radius.
        max: f64,
    },
}

/// An axis-aligned region.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Lower corner, m.
    pub min: Vec3,
    /// Upper corner, m.
    pub max: Vec3,
}

/// One explicitly placed grain.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrainSpec {
    /// Centre, m.
    pub position: Vec3,
    /// Radius, m.
    pub radius: f64,
    /// Velocity, m/s. Default: 0.
    #[serde(default)]
    pub velocity: Vec3,
    /// Angular velocity, rad/s. Default: 0.
    #[serde(default)]
    pub angular_velocity: Vec3,
}

/// Where grains come from.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum GrainSource {
    /// An explicit list.
    List {
        /// Material name.
        material: String,
        /// The grains.
        grains: Vec<GrainSpec>,
    },
    /// A simple cubic (2-D: square) lattice filling a region.
    Lattice {
        /// Material name.
        material: String,
        /// Radius, m.
        radius: f64,
        /// Region filled (centres stay a radius inside it).
        region: Region,
        /// Distance between neighbouring centres, m. Default: 2.1 × radius.
        #[serde(default)]
        spacing: Option<f64>,
        /// Initial velocity, m/s. Default: 0.
        #[serde(default)]
        velocity: Vec3,
    },
    /// Random sequential insertion without overlap.
    Random {
        /// Material name.
        material: String,
        /// Region the grains must lie inside.
        region: Region,
        /// Number of grains.
        count: usize,
        /// Radius distribution.
        radius: RadiusSpec,
        /// Seed of the random generator.
        seed: u64,
        /// Random velocities uniform in [−v, v] per component, m/s. Default: 0.
        #[serde(default)]
        velocity_spread: f64,
    },
    /// Grains read from a LAMMPS data file (`atom_style sphere`): positions, diameters,
    /// densities and, if the file has them, velocities and angular velocities.
    LammpsData {
        /// The data file, relative to the scene file.
        file: String,
        /// Which material (and whether frozen) each atom type becomes.
        types: Vec<LammpsType>,
        /// Copies of the file's atoms along x, y, z, each shifted by the file's box length
        /// on that axis (`(2, 2, 1)`: four copies side by side). Default: (1, 1, 1).
        #[serde(default)]
        replicate: Option<(u32, u32, u32)>,
    },
}

/// The material of one LAMMPS atom type: `(type: 2, material: "base", frozen: true)`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LammpsType {
    /// The atom type number.
    #[serde(rename = "type")]
    pub atom_type: u32,
    /// Material name (its density is replaced by each atom's own).
    pub material: String,
    /// Frozen grains never move but take part in contacts. Default: false.
    #[serde(default)]
    pub frozen: bool,
}

fn default_interval() -> f64 {
    0.01
}
fn default_true() -> bool {
    true
}

/// Outputs of a run.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Write a rerun recording. Default: true.
    #[serde(default = "default_true")]
    pub recording: bool,
    /// Simulated time between recording frames, s. Default: 0.01.
    #[serde(default = "default_interval")]
    pub recording_interval: f64,
    /// Simulated time between report samples, s. Default: 0.01.
    #[serde(default = "default_interval")]
    pub report_interval: f64,
    /// Write the final state (every grain, wall and contact with its history) to
    /// `state.ron`, for `talus run --resume` or another scene's `start_from`. Default: false.
    #[serde(default)]
    pub state: bool,
    /// Book the contacts' energies at every step (elastic energy, dissipation per
    /// mechanism, work of moving walls, integration error) for the report's energy
    /// balance. `false` skips those sums in the force loop, the forces and trajectory
    /// unchanged bit for bit; the report then leaves the balance out. Default: true.
    #[serde(default = "default_true")]
    pub energy_ledger: bool,
}

impl Default for OutputSpec {
    fn default() -> Self {
        Self {
            recording: true,
            recording_interval: default_interval(),
            report_interval: default_interval(),
            state: false,
            energy_ledger: true,
        }
    }
}

/// A servo on a plane wall: `servo: (pressure: 1e4, area: 0.0004, gain: 1e-3)`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoSpec {
    /// Target pressure on the wall, Pa (compressive positive).
    pub pressure: f64,
    /// Area the pressure acts on, m² (2-D: length × 1 m).
    pub area: f64,
    /// Wall speed per newton of load error, m/(s N).
    pub gain: f64,
    /// Largest wall speed, m/s. Default: unbounded.
    #[serde(default)]
    pub max_speed: Option<f64>,
}

/// A plane wall moved at a set strain rate: `strain_rate: (rate: 0.1, opposite: "z_min")`.
/// The gap L to the opposite (parallel, facing) wall then follows L̇ = −rate · L.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrainRateSpec {
    /// True strain rate of the gap, 1/s: positive compresses, negative extends.
    pub rate: f64,
    /// Name of the opposite wall the gap is measured to (a plane's name or a box face
    /// such as "z_min").
    pub opposite: String,
}

/// Periodic boundaries: `periodic: (x: (0.0, 0.1), y: (0.0, 0.1))`. Each axis given is
/// periodic over `[min, max)`; grains leaving through one face come back through the other.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeriodicSpec {
    /// Extent (min, max) of the x axis, m, if x is periodic.
    #[serde(default)]
    pub x: Option<(f64, f64)>,
    /// Extent of the y axis, if periodic.
    #[serde(default)]
    pub y: Option<(f64, f64)>,
    /// Extent of the z axis, if periodic (3-D scenes only).
    #[serde(default)]
    pub z: Option<(f64, f64)>,
    /// Lees–Edwards simple shear between the periodic images along `gradient`. Default:
    /// none (plain periodic box).
    #[serde(default)]
    pub shear: Option<ShearSpec>,
}

fn default_true_flag() -> bool {
    true
}

/// Lees–Edwards shear of the periodic box:
/// `shear: (rate: 10.0, flow: "x", gradient: "z")`. The images one box length up the
/// gradient axis slide along the flow axis at `rate × L_gradient`, imposing the mean flow
/// v_flow = rate × (x_gradient − middle of the box).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShearSpec {
    /// Shear rate γ̇ = ∂v_flow/∂x_gradient, 1/s (either sign).
    pub rate: f64,
    /// Flow axis: "x", "y" or "z" (periodic).
    pub flow: String,
    /// Gradient axis: "x", "y" or "z" (periodic, not the flow axis).
    pub gradient: String,
    /// Add the streaming velocity to every grain's initial velocity, so that the run
    /// starts on the shear profile instead of at rest. Default: true.
    #[serde(default = "default_true_flag")]
    pub start_on_profile: bool,
}

/// Stress sampling: `sampling: (interval: 0.01, domain: true, regions: [...])`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamplingSpec {
    /// Simulated time between stress samples, s. Default: `output.report_interval`.
    #[serde(default)]
    pub interval: Option<f64>,
    /// Sample the whole domain (reported as region `domain`). Default: true.
    #[serde(default = "default_true")]
    pub domain: bool,
    /// Regions sampled besides the domain.
    #[serde(default)]
    pub regions: Vec<SamplingRegion>,
    /// Coarse-grained fields on a grid over the domain box. Default: none.
    #[serde(default)]
    pub fields: Option<SamplingFields>,
}

/// Coarse-grained fields: `fields: (cells: (20, 20, 20), width: 0.002)`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamplingFields {
    /// Grid cells along x, y, z over the domain box (z = 1 in 2-D).
    pub cells: (u32, u32, u32),
    /// Kernel width w (standard deviation of the Gaussian), m.
    pub width: f64,
    /// Simulated time between field samples, s. Default: the sampling interval.
    #[serde(default)]
    pub interval: Option<f64>,
}

/// A region in which stresses are sampled.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum SamplingRegion {
    /// An axis-aligned box.
    Box {
        /// Name in reports and recordings.
        name: String,
        /// Lower corner, m.
        min: Vec3,
        /// Upper corner, m.
        max: Vec3,
        /// Imposed shear rate for the inertial number, 1/s. Default: estimated.
        #[serde(default)]
        shear_rate: Option<f64>,
    },
    /// A layer between two planes normal to an axis, spanning the domain along the others.
    Slab {
        /// Name in reports and recordings.
        name: String,
        /// "x", "y" or "z".
        axis: String,
        /// Lower bound along the axis, m.
        min: f64,
        /// Upper bound along the axis, m.
        max: f64,
        /// Imposed shear rate for the inertial number, 1/s. Default: estimated.
        #[serde(default)]
        shear_rate: Option<f64>,
    },
}
