//! Talus stress sampling: the Love–Weber contact stress, the kinetic stress, the couple
//! stress and the inertial number, over the whole domain and over boxes and slabs a
//! scene defines, and coarse-grained fields (density, velocity, stress) on a grid, as
//! plugins that are only built when a scene asks for them.
//!
//! The physics and every convention (tension positive, p = −tr σ / D, branch vectors,
//! clipping of contacts that cross a region's boundary, volumes, the shear-rate fit) are
//! documented in `docs/physics/stress.md`.
//!
//! ```no_run
//! # use talus_core::prelude::*;
//! # fn scene(builder: &mut SimBuilder) {
//! use talus_stress::{RegionShape, RegionSpec, StressPlugin};
//! builder.add_plugin(&StressPlugin {
//!     every: 100,
//!     regions: vec![
//!         RegionSpec { name: "domain".into(), shape: RegionShape::Domain, shear_rate: None },
//!         RegionSpec {
//!             name: "bottom".into(),
//!             shape: RegionShape::Slab { axis: 2, min: 0.0, max: 0.01 },
//!             shear_rate: None,
//!         },
//!     ],
//! });
//! // After stepping: world.resource::<talus_stress::StressRecord>().latest
//! # }
//! ```

pub mod field;
pub mod region;
pub mod sample;
pub mod tensor;

pub use field::{
    CoarseGrainingPlugin, FIELD_SYSTEM_NAME, FieldRecord, FieldSample, FieldSettings, FieldSpec,
    sample_fields,
};
pub use region::{Bounds, RegionKind, RegionShape, RegionSpec, Seams, ShearedSeam};
pub use sample::{
    FlowRegime, GAS_LIKE_LIMIT, QUASI_STATIC_LIMIT, RegionStress, ShearRateSource, StressRecord,
    StressSample, StressScratch, StressSettings, sample_stress,
};
pub use tensor::Tensor;

use talus_core::schedule::{Plugin, SimBuilder, Stage};

/// Name of the sampling system in the plan.
pub const SYSTEM_NAME: &str = "stress_sampling";

/// The stress sampling plugin: adds [`sample_stress`] to [`Stage::Sample`] and the
/// [`StressSettings`] and [`StressRecord`] resources. Build it only when stresses are
/// wanted; without it nothing stress-related runs.
#[derive(Clone, Debug, PartialEq)]
pub struct StressPlugin {
    /// Sample every this many steps (0 is treated as 1); step 0 is always sampled.
    pub every: u64,
    /// The regions, in report order.
    pub regions: Vec<RegionSpec>,
}

impl Plugin for StressPlugin {
    fn name(&self) -> String {
        SYSTEM_NAME.into()
    }

    fn build(&self, sim: &mut SimBuilder) {
        let every = self.every.max(1);
        let names: Vec<String> = self
            .regions
            .iter()
            .map(|r| match r.shape {
                RegionShape::Domain => r.name.clone(),
                RegionShape::Box { .. } => format!("{} (box)", r.name),
                RegionShape::Slab { axis, .. } => {
                    format!(
                        "{} (slab {})",
                        r.name,
                        ["x", "y", "z"].get(axis).unwrap_or(&"?")
                    )
                }
            })
            .collect();
        sim.note(format!(
            "stress sampling every {every} step(s): {}",
            if names.is_empty() {
                "no region".to_string()
            } else {
                names.join(", ")
            }
        ));
        sim.world.insert_resource(StressSettings {
            every,
            regions: self.regions.clone(),
        });
        sim.world.insert_resource(StressRecord::default());
        sim.add_system(Stage::Sample, SYSTEM_NAME, sample_stress);
    }
}
