//! Gear predictor–corrector integration (the sixth-value scheme of Allen & Tildesley for
//! positions, the four-value scheme for angular velocities): a higher-order alternative
//! to the leapfrog for accuracy studies. Predict every scaled derivative by Taylor series,
//! evaluate the forces at the predicted state, then correct each derivative by the
//! difference between the computed and the predicted acceleration.
//!
//! The derivatives are kept in a resource in grain query order (grains are neither added
//! nor removed during a run; a change of count resets them). Frozen grains are skipped.

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::*;
use crate::energy::EnergyLedger;
use crate::resources::{Clock, SimConfig};

/// Corrector coefficients of the six-value Gear scheme for second-order equations
/// (Gear 1971; Allen & Tildesley table E.1), for r, dt r', dt²/2 r'', ..., dt⁵/120 r⁽⁵⁾.
const POSITION_CORRECTOR: [f64; 6] = [
    3.0 / 16.0,
    251.0 / 360.0,
    1.0,
    11.0 / 18.0,
    1.0 / 6.0,
    1.0 / 60.0,
];

/// Corrector coefficients of the four-value Gear scheme for first-order equations, for
/// ω, dt ω', dt²/2 ω'', dt³/6 ω'''.
const SPIN_CORRECTOR: [f64; 4] = [3.0 / 8.0, 1.0, 3.0 / 4.0, 1.0 / 6.0];

/// Scaled higher derivatives of every moving grain, in query order (saved with a state).
#[derive(Resource, Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GearHistory {
    /// Per grain: dt²/2 r'', dt³/6 r''', dt⁴/24 r⁗, dt⁵/120 r⁽⁵⁾.
    position: Vec<[DVec3; 4]>,
    /// Per grain: dt ω', dt²/2 ω'', dt³/6 ω'''.
    spin: Vec<[DVec3; 3]>,
    /// Positions before the prediction, for the work of gravity.
    start: Vec<DVec3>,
}

impl GearHistory {
    /// Follows a reordering of the moving grains (`before` and `after`: their entities in
    /// query order), so that each grain keeps its own derivatives
    /// ([`crate::grain_order::sort_grains`]). A history not yet started is left empty.
    pub(crate) fn reorder(&mut self, before: &[Entity], after: &[Entity]) {
        if self.position.len() != before.len() || before.len() != after.len() {
            return;
        }
        let old_index: std::collections::HashMap<Entity, usize> =
            before.iter().enumerate().map(|(k, e)| (*e, k)).collect();
        let order: Vec<usize> = after.iter().map(|e| old_index[e]).collect();
        self.position = order.iter().map(|&k| self.position[k]).collect();
        self.spin = order.iter().map(|&k| self.spin[k]).collect();
        // `start` is refilled by each prediction before the correction reads it.
        self.start.clear();
    }
}

/// Predictor: Taylor-series step of positions, velocities and spins (and their scaled
/// derivatives). Starts the derivatives from the current forces on first use.
#[allow(clippy::type_complexity)]
pub fn gear_predict(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    mut history: ResMut<GearHistory>,
    mut grains: Query<
        (
            &mut Position,
            &mut Velocity,
            &mut AngularVelocity,
            &Force,
            &Torque,
            &Mass,
            &MomentOfInertia,
        ),
        (With<Grain>, Without<Frozen>),
    >,
) {
    let dt = clock.pass_dt;
    if dt == 0.0 {
        return;
    }
    let n = grains.iter().len();
    let h = &mut *history;
    if h.position.len() != n {
        h.position.clear();
        h.spin.clear();
        for (_, _, _, f, t, m, i) in grains.iter() {
            h.position.push([
                f.0 * (0.5 * dt * dt / m.0),
                DVec3::ZERO,
                DVec3::ZERO,
                DVec3::ZERO,
            ]);
            let spin_rate = if config.rotation {
                t.0 * (dt / i.0)
            } else {
                DVec3::ZERO
            };
            h.spin.push([spin_rate, DVec3::ZERO, DVec3::ZERO]);
        }
    }
    h.start.clear();
    for (k, (mut p, mut v, mut w, ..)) in grains.iter_mut().enumerate() {
        h.start.push(p.0);
        let [r2, r3, r4, r5] = &mut h.position[k];
        let mut r1 = v.0 * dt;
        // Pascal-triangle prediction of the scaled derivatives.
        p.0 += r1 + *r2 + *r3 + *r4 + *r5;
        r1 += 2.0 * *r2 + 3.0 * *r3 + 4.0 * *r4 + 5.0 * *r5;
        *r2 += 3.0 * *r3 + 6.0 * *r4 + 10.0 * *r5;
        *r3 += 4.0 * *r4 + 10.0 * *r5;
        *r4 += 5.0 * *r5;
        v.0 = r1 / dt;
        if config.rotation {
            let [w1, w2, w3] = &mut h.spin[k];
            w.0 += *w1 + *w2 + *w3;
            *w1 += 2.0 * *w2 + 3.0 * *w3;
            *w2 += 3.0 * *w3;
        }
    }
}

/// Corrector: the forces of the predicted state give the acceleration; every scaled
/// derivative moves by its coefficient times the acceleration's misprediction. Books the
/// work of gravity over the corrected displacement.
#[allow(clippy::type_complexity)]
pub fn gear_correct(
    config: Res<SimConfig>,
    clock: Res<Clock>,
    mut history: ResMut<GearHistory>,
    mut ledger: ResMut<EnergyLedger>,
    mut grains: Query<
        (
            &mut Position,
            &mut Velocity,
            &mut AngularVelocity,
            &Force,
            &Torque,
            &Mass,
            &MomentOfInertia,
        ),
        (With<Grain>, Without<Frozen>),
    >,
) {
    let dt = clock.pass_dt;
    if dt == 0.0 {
        return;
    }
    let h = &mut *history;
    let g = config.gravity;
    let mut gravity_work = 0.0;
    for (k, (mut p, mut v, mut w, f, t, m, i)) in grains.iter_mut().enumerate() {
        let [r2, r3, r4, r5] = &mut h.position[k];
        let delta = f.0 * (0.5 * dt * dt / m.0) - *r2;
        let c = POSITION_CORRECTOR;
        p.0 += c[0] * delta;
        v.0 += c[1] * delta / dt;
        *r2 += c[2] * delta;
        *r3 += c[3] * delta;
        *r4 += c[4] * delta;
        *r5 += c[5] * delta;
        gravity_work += m.0 * g.dot(p.0 - h.start[k]);
        if config.rotation {
            let [w1, w2, w3] = &mut h.spin[k];
            let delta = t.0 * (dt / i.0) - *w1;
            let c = SPIN_CORRECTOR;
            w.0 += c[0] * delta;
            *w1 += c[1] * delta;
            *w2 += c[2] * delta;
            *w3 += c[3] * delta;
        }
    }
    ledger.gravity_work += gravity_work;
}
