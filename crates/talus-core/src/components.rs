//! Components of grains and walls: the state the integrators advance.

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::resources::Dimension;

/// Marks an entity as a grain (a sphere in 3-D, a disk in the xy-plane in 2-D).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct Grain;

/// Centre position of a grain, metres.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Position(pub DVec3);

/// Translational velocity of a grain, m/s.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Velocity(pub DVec3);

/// Angular velocity of a grain, rad/s. In 2-D only the z component is used.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct AngularVelocity(pub DVec3);

/// Radius of a grain, metres.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Radius(pub f64);

/// Mass of a grain, kg.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Mass(pub f64);

/// Marks a grain that never moves (a rough base, a fixed obstacle): it takes part in
/// contacts, but no integrator touches it, and contact laws see it with infinite mass.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct Frozen;

/// Moment of inertia of a grain about any axis through its centre, kg m².
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct MomentOfInertia(pub f64);

/// Index of a material in [`crate::resources::Materials`].
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MaterialId(pub u16);

/// Force accumulated on a grain during the current step, N.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Force(pub DVec3);

/// Torque accumulated on a grain during the current step, N m.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct Torque(pub DVec3);

/// All components of one grain, spawned together so that a grain never changes archetype.
#[derive(Bundle, Clone, Debug)]
pub struct GrainBundle {
    /// Marker.
    pub grain: Grain,
    /// Centre position.
    pub position: Position,
    /// Translational velocity.
    pub velocity: Velocity,
    /// Angular velocity.
    pub angular_velocity: AngularVelocity,
    /// Radius.
    pub radius: Radius,
    /// Mass.
    pub mass: Mass,
    /// Moment of inertia.
    pub inertia: MomentOfInertia,
    /// Material.
    pub material: MaterialId,
    /// Force accumulator.
    pub force: Force,
    /// Torque accumulator.
    pub torque: Torque,
}

impl GrainBundle {
    /// A grain at rest of the given radius and density. In 3-D a solid sphere
    /// (m = 4/3 π ρ R³, I = 2/5 m R²); in 2-D a disk of unit thickness
    /// (m = π ρ R² · 1 m, I = 1/2 m R²).
    pub fn new(
        dimension: Dimension,
        position: DVec3,
        radius: f64,
        density: f64,
        material: MaterialId,
    ) -> Self {
        let (mass, inertia) = mass_and_inertia(dimension, radius, density);
        Self {
            grain: Grain,
            position: Position(position),
            velocity: Velocity(DVec3::ZERO),
            angular_velocity: AngularVelocity(DVec3::ZERO),
            radius: Radius(radius),
            mass: Mass(mass),
            inertia: MomentOfInertia(inertia),
            material,
            force: Force(DVec3::ZERO),
            torque: Torque(DVec3::ZERO),
        }
    }

    /// Sets the initial translational velocity.
    pub fn with_velocity(mut self, velocity: DVec3) -> Self {
        self.velocity = Velocity(velocity);
        self
    }

    /// Sets the initial angular velocity.
    pub fn with_angular_velocity(mut self, omega: DVec3) -> Self {
        self.angular_velocity = AngularVelocity(omega);
        self
    }
}

/// Mass and moment of inertia of a solid sphere (3-D) or a unit-thickness disk (2-D).
pub fn mass_and_inertia(dimension: Dimension, radius: f64, density: f64) -> (f64, f64) {
    match dimension {
        Dimension::Three => {
            let m = 4.0 / 3.0 * std::f64::consts::PI * density * radius.powi(3);
            (m, 0.4 * m * radius * radius)
        }
        Dimension::Two => {
            let m = std::f64::consts::PI * density * radius * radius;
            (m, 0.5 * m * radius * radius)
        }
    }
}

/// An infinite plane wall: grains live on the side its outward normal points to.
/// It may translate with a prescribed velocity; it is never pushed by grains.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct Wall {
    /// Name shown in reports and recordings.
    pub name: String,
    /// A point on the plane, metres (moves with `velocity`).
    pub point: DVec3,
    /// Unit normal pointing into the region where grains are.
    pub normal: DVec3,
    /// Prescribed velocity of the plane, m/s.
    pub velocity: DVec3,
    /// Material of the wall surface.
    pub material: MaterialId,
}

/// Force the grains exert on a wall during the current step, N.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct WallLoad(pub DVec3);

/// A wall moved by a servo: along its normal, at a speed proportional to the difference
/// between a target load and the load the grains put on it, so that it holds a pressure.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Servo {
    /// Target compressive load on the wall, N (pressure × area).
    pub target_load: f64,
    /// Speed per newton of load error, m/(s N).
    pub gain: f64,
    /// Largest speed, m/s.
    pub max_speed: f64,
}

/// A wall moved at a set strain rate against an opposite, parallel wall: along its
/// normal at about `share · rate · L`, L the current gap between the two planes, so that
/// the gap follows L̇ = −rate · L (positive rate compresses, negative extends). When both
/// walls of the pair are driven, each has `share` ½.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct StrainRateDrive {
    /// True strain rate of the gap, 1/s (compression positive).
    pub rate: f64,
    /// The wall the gap is measured to.
    pub opposite: Entity,
    /// Part of the gap's rate this wall makes: 1, or ½ when the opposite wall is driven too.
    pub share: f64,
}

/// All components of one wall.
#[derive(Bundle, Clone, Debug)]
pub struct WallBundle {
    /// The plane.
    pub wall: Wall,
    /// Load accumulator.
    pub load: WallLoad,
}

impl WallBundle {
    /// A wall through `point` with outward `normal` (normalised here), at rest.
    pub fn new(name: impl Into<String>, point: DVec3, normal: DVec3, material: MaterialId) -> Self {
        Self {
            wall: Wall {
                name: name.into(),
                point,
                normal: normal.normalize(),
                velocity: DVec3::ZERO,
                material,
            },
            load: WallLoad::default(),
        }
    }

    /// Sets a prescribed velocity.
    pub fn with_velocity(mut self, velocity: DVec3) -> Self {
        self.wall.velocity = velocity;
        self
    }
}
