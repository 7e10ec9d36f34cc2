//! HDEM hysteresis rolling resistance (seed 001) in the free-rocking experiment: a disk
//! (or sphere) rolls on a rigid floor, stops under the rolling slider and rocks about
//! its rest position, once with the conventional elastic–plastic spring–dashpot part and
//! once with HDEM, both from the same initial state (equal initial energy).
//!
//! References (independent of the code): the conventional model is the damped linear
//! oscillator J_z θ̈ + c_r θ̇ + K_r θ = 0 of seed 001 eq. (18), J_z = 3/2 m R² for a disk,
//! so its frequency is ω_d = ω √(1 − ζ²), ω = √(K_r/J_z), at every amplitude, and its
//! velocity peaks decay by exp(−π ζ/√(1 − ζ²)) per half period. HDEM's power-law
//! branches have a secant stiffness K_r (A/Δ_e)^(β−1) that grows as the amplitude A
//! falls, and lose the fraction 1 − β of the energy per half cycle whatever the rate.

use crate::common;

use talus::cli::ReportSample;

const GRAVITY: f64 = 9.81;
const RADIUS: f64 = 0.01; // m
const DENSITY: f64 = 1200.0; // kg/m³, polyurethane
const NORMAL_STIFFNESS: f64 = 1e6; // N/m
/// Target rocking angular frequency ω = √(K_r/J_z), rad/s.
const ROCKING_FREQUENCY: f64 = 50.0;
const ROLLING_FRICTION: f64 = 0.05;
/// Damping ratio identified for the conventional model.
const CONVENTIONAL_ZETA: f64 = 0.05;
/// HDEM's dashpot: smaller, since its hysteresis spring also dissipates (chosen so that
/// both models lose about the same energy per cycle at the start of the rocking, as the
/// paper's fitted curves do: e^{−2πζ_c} ≈ β e^{−2πζ_h}).
const HDEM_ZETA: f64 = 0.02;
const BETA: f64 = 0.844;
const SPEED: f64 = 0.01; // m/s, initial rolling speed
const DURATION: f64 = 3.0; // s
/// Long enough for both models to fall below 1e-4 of the initial spin.
const REST_DURATION: f64 = 4.5; // s

/// Mass of the grain: a disk of 1 m thickness in 2-D, a sphere in 3-D.
fn mass(dimension: u8) -> f64 {
    if dimension == 3 {
        4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3) * DENSITY
    } else {
        std::f64::consts::PI * RADIUS * RADIUS * DENSITY
    }
}

/// J_z = J_c + m R², the inertia about the contact point.
fn contact_inertia(dimension: u8) -> f64 {
    let kappa = if dimension == 3 { 1.4 } else { 1.5 };
    kappa * mass(dimension) * RADIUS * RADIUS
}

/// K_r = ω² J_z (seed 001 eq. (23)).
fn rolling_stiffness(dimension: u8) -> f64 {
    ROCKING_FREQUENCY * ROCKING_FREQUENCY * contact_inertia(dimension)
}

/// The rolling part of the conventional model.
fn conventional(dimension: u8) -> String {
    format!(
        r#"rolling: "elastic_plastic", rolling_friction: {ROLLING_FRICTION}, rolling_stiffness: {:e}, rolling_damping_ratio: {CONVENTIONAL_ZETA}"#,
        rolling_stiffness(dimension)
    )
}

/// The rolling part of HDEM.
fn hdem(dimension: u8) -> String {
    format!(
        r#"rolling: "hdem", rolling_friction: {ROLLING_FRICTION}, rolling_stiffness: {:e}, rolling_damping_ratio: {HDEM_ZETA}, hysteresis_exponent: {BETA}"#,
        rolling_stiffness(dimension)
    )
}

/// One grain on a floor at its equilibrium overlap, rolling along +x without slip.
fn scene(dimension: u8, contact: &str, duration: f64) -> String {
    let overlap = mass(dimension) * GRAVITY / NORMAL_STIFFNESS;
    let height = RADIUS - overlap;
    let spin = SPEED / (RADIUS - 0.5 * overlap);
    let (gravity, normal, position, omega) = if dimension == 3 {
        (
            "(0.0, 0.0, -9.81)",
            "(0.0, 0.0, 1.0)",
            format!("(0.0, 0.0, {height:e})"),
            format!("(0.0, {spin:e}, 0.0)"),
        )
    } else {
        (
            "(0.0, -9.81, 0.0)",
            "(0.0, 1.0, 0.0)",
            format!("(0.0, {height:e}, 0.0)"),
            format!("(0.0, 0.0, {:e})", -spin),
        )
    };
    format!(
        r#"Scene(
    name: "hdem-rocking",
    dimension: {dimension},
    gravity: {gravity},
    duration: {duration},
    plugins: ["linear_spring"],
    materials: [(name: "polyurethane", density: {DENSITY:e},
        contact: (law: "linear_spring", stiffness: {NORMAL_STIFFNESS:e}, restitution: 0.5, friction: 0.5, tangential_damping_ratio: 1.0, {contact}))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: {normal}, material: "polyurethane")],
    grains: [List(material: "polyurethane", grains: [
        (position: {position}, radius: {RADIUS:e}, velocity: ({SPEED:e}, 0.0, 0.0), angular_velocity: {omega}),
    ])],
    output: (recording: false),
)"#
    )
}

/// Rolling spin about the axis that rolls the grain along +x.
fn rolling_spin(dimension: u8, omega: glam::DVec3) -> f64 {
    if dimension == 3 { omega.y } else { -omega.z }
}

/// Time series of one rocking run, one entry per step.
struct Run {
    dt: f64,
    time: Vec<f64>,
    spin: Vec<f64>,
    /// Rolling angle ∫ω dt, rad.
    angle: Vec<f64>,
    kinetic: Vec<f64>,
    hysteresis: Vec<f64>,
    damping: Vec<f64>,
    slip: Vec<f64>,
    /// Largest |E_book(t) − E_book(first step)| over the run, J.
    bookkeeping_drift: f64,
    initial_kinetic: f64,
}

fn run(dimension: u8, contact: &str, duration: f64) -> Run {
    let (mut sim, steps) = common::build(&scene(dimension, contact, duration));
    sim.prime().unwrap();
    let initial_kinetic = ReportSample::take(&sim.world).kinetic();
    let dt = sim.config().dt;
    let n = steps as usize;
    let mut out = Run {
        dt,
        time: Vec::with_capacity(n),
        spin: Vec::with_capacity(n),
        angle: Vec::with_capacity(n),
        kinetic: Vec::with_capacity(n),
        hysteresis: Vec::with_capacity(n),
        damping: Vec::with_capacity(n),
        slip: Vec::with_capacity(n),
        bookkeeping_drift: 0.0,
        initial_kinetic,
    };
    let mut angle = 0.0;
    let mut first_balance = None;
    for step in 1..=steps {
        sim.step().unwrap();
        let s = ReportSample::take(&sim.world);
        let w = rolling_spin(dimension, common::grains(&mut sim)[0].omega);
        angle += w * dt;
        let channel = |name: &str| s.dissipated.get(name).copied().unwrap_or(0.0);
        out.time.push(step as f64 * dt);
        out.spin.push(w);
        out.angle.push(angle);
        out.kinetic.push(s.kinetic());
        out.hysteresis.push(channel("rolling_hysteresis"));
        out.damping.push(channel("rolling_damping"));
        out.slip.push(channel("rolling_slip"));
        // The reference is the first step's sample: the priming pass has no staggering
        // term (see tests/rolling_resistance.rs).
        let first = *first_balance.get_or_insert(s.bookkeeping_balance);
        out.bookkeeping_drift = out
            .bookkeeping_drift
            .max((s.bookkeeping_balance - first).abs());
    }
    out
}

/// Half cycles of the rocking, between successive zero crossings of the spin (the
/// turning points of the angle), interpolated linearly.
struct HalfCycle {
    /// Start and end time, s.
    start: f64,
    end: f64,
    /// Largest |ω| within, rad/s.
    peak: f64,
    /// Step indices of the start and end.
    first: usize,
    last: usize,
}

impl Run {
    fn half_cycles(&self) -> Vec<HalfCycle> {
        let mut crossings = Vec::new();
        for k in 1..self.spin.len() {
            let (a, b) = (self.spin[k - 1], self.spin[k]);
            if a != 0.0 && a * b <= 0.0 {
                let t = self.time[k - 1] + self.dt * a / (a - b);
                crossings.push((t, k));
            }
        }
        crossings
            .windows(2)
            .map(|w| HalfCycle {
                start: w[0].0,
                end: w[1].0,
                peak: self.spin[w[0].1..w[1].1]
                    .iter()
                    .fold(0.0f64, |m, x| m.max(x.abs())),
                first: w[0].1,
                last: w[1].1,
            })
            .collect()
    }

    /// End of the last half cycle whose spin peak reaches `threshold`: from then on
    /// the rocking envelope stays below it, s (the run's end if it never falls below).
    fn rest_time(&self, threshold: f64) -> f64 {
        let cycles = self.half_cycles();
        match cycles.iter().rposition(|c| c.peak >= threshold) {
            Some(k) if k + 1 < cycles.len() => cycles[k].end,
            Some(_) => *self.time.last().unwrap_or(&0.0),
            None => 0.0,
        }
    }
}

/// Half cycles whose peak lies between `high` and `low` times the first rocking peak:
/// away from the start (slider) and from the noise floor.
fn rocking_window(cycles: &[HalfCycle], high: f64, low: f64) -> Vec<&HalfCycle> {
    let first = cycles.first().map_or(0.0, |c| c.peak);
    cycles
        .iter()
        .filter(|c| c.peak <= high * first && c.peak >= low * first)
        .collect()
}

/// Conventional model: the half periods stay at π/ω_d within 1 % from the first
/// rocking cycles down to 1e-4 of their amplitude, and the velocity peaks decay by
/// the ratio ζ gives.
#[test]
fn conventional_rocking_has_constant_frequency_and_decays_at_zeta() {
    let r = run(2, &conventional(2), DURATION);
    let cycles = r.half_cycles();
    let window = rocking_window(&cycles, 0.5, 1e-4);
    assert!(window.len() >= 10, "only {} half cycles", window.len());
    let omega = ROCKING_FREQUENCY;
    let damped = omega * (1.0 - CONVENTIONAL_ZETA * CONVENTIONAL_ZETA).sqrt();
    let frequencies: Vec<f64> = window
        .iter()
        .map(|c| std::f64::consts::PI / (c.end - c.start))
        .collect();
    let (lo, hi) = frequencies
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), f| (l.min(*f), h.max(*f)));
    let mean = frequencies.iter().sum::<f64>() / frequencies.len() as f64;
    // ζ from the decrement of successive peaks: ln(p_k/p_{k+1}) = π ζ/√(1 − ζ²).
    let decrement =
        (window[0].peak / window[window.len() - 1].peak).ln() / (window.len() - 1) as f64;
    let zeta = decrement / (std::f64::consts::PI.powi(2) + decrement * decrement).sqrt();
    eprintln!(
        "conventional: {} half cycles, ω from crossings {lo:.4}..{hi:.4} rad/s (spread {:.2e}), mean {mean:.4}, \
         analytic ω_d {damped:.4} rad/s; ζ measured {zeta:.5}, set {CONVENTIONAL_ZETA}",
        window.len(),
        (hi - lo) / mean
    );
    assert!((hi - lo) / mean < 0.01, "frequency spread {lo}..{hi}");
    assert!(
        (mean - damped).abs() / damped < 0.01,
        "mean ω {mean}, analytic {damped}"
    );
    assert!(
        (zeta - CONVENTIONAL_ZETA).abs() / CONVENTIONAL_ZETA < 0.01,
        "ζ measured {zeta}"
    );
}

/// HDEM: the frequency from successive half periods rises over the last cycles as the
/// amplitude dies out, and the disk comes to rest sooner than the conventional one.
#[test]
fn hdem_frequency_rises_and_it_rests_sooner() {
    let h = run(2, &hdem(2), REST_DURATION);
    let c = run(2, &conventional(2), REST_DURATION);
    let cycles = h.half_cycles();
    let window = rocking_window(&cycles, 0.5, 1e-4);
    let frequencies: Vec<f64> = window
        .iter()
        .map(|c| std::f64::consts::PI / (c.end - c.start))
        .collect();
    eprintln!(
        "HDEM: ω of {} half cycles from crossings: {}",
        frequencies.len(),
        frequencies
            .iter()
            .map(|f| format!("{f:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    assert!(
        frequencies.len() >= 8,
        "only {} half cycles",
        frequencies.len()
    );
    // Over the last cycles, each full cycle (two half cycles, so that the asymmetry
    // between the halves cancels) is faster than the one before.
    let full: Vec<f64> = frequencies
        .chunks_exact(2)
        .map(|p| 2.0 / (1.0 / p[0] + 1.0 / p[1]))
        .collect();
    let last = &full[full.len().saturating_sub(4)..];
    for pair in last.windows(2) {
        assert!(pair[1] > pair[0], "frequency not rising: {last:?}");
    }
    let rise = full[full.len() - 1] / full[0];
    assert!(rise > 1.1, "frequency rose by {rise} only");
    let threshold = 1e-4 * SPEED / RADIUS;
    let (t_h, t_c) = (h.rest_time(threshold), c.rest_time(threshold));
    eprintln!(
        "at rest (|ω| < {threshold:.1e} rad/s for good): HDEM after {t_h:.3} s, conventional after {t_c:.3} s; \
         frequency rise over the window {rise:.3}"
    );
    assert!(
        t_h < t_c,
        "HDEM at rest after {t_h} s, conventional after {t_c} s"
    );
}

/// Near rest the hysteresis spring takes a growing share of the dissipation: its loss
/// per half cycle over the dashpot's rises from the first rocking cycles to the last.
#[test]
fn hdem_hysteresis_share_grows_near_rest() {
    let h = run(2, &hdem(2), DURATION);
    let cycles = h.half_cycles();
    let window = rocking_window(&cycles, 0.5, 1e-4);
    let ratios: Vec<f64> = window
        .iter()
        .map(|c| {
            let hyst = h.hysteresis[c.last] - h.hysteresis[c.first];
            let damp = h.damping[c.last] - h.damping[c.first];
            hyst / damp
        })
        .collect();
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let k = ratios.len() / 4;
    let (early, late) = (mean(&ratios[..k]), mean(&ratios[ratios.len() - k..]));
    eprintln!(
        "hysteresis / dashpot loss per half cycle: first quarter {early:.3}, last quarter {late:.3} ({} half cycles)",
        ratios.len()
    );
    assert!(late > 1.1 * early, "share early {early}, late {late}");
}

/// Near rest the spin does not flip sign at the step frequency: in the last second of a
/// 6 s run (spin below 1e-5 of its initial value) the sign changes are as few as the
/// rocking at its stiffest allows, far fewer than one per step.
#[test]
fn hdem_does_not_chatter_at_rest() {
    const LONG: f64 = 6.0;
    let h = run(2, &hdem(2), LONG);
    let start = h.time.iter().position(|t| *t >= LONG - 1.0).unwrap();
    let flips = h.spin[start..]
        .windows(2)
        .filter(|w| w[0] * w[1] < 0.0)
        .count();
    let steps = h.spin.len() - start;
    let largest = h.spin[start..].iter().fold(0.0f64, |m, w| m.max(w.abs()));
    // The stiffest branch (ceiling 10 K_r) rocks at √10 ω: 2 √10 ω/π sign changes per second.
    let bound = (2.0 * 10f64.sqrt() * ROCKING_FREQUENCY / std::f64::consts::PI).ceil() as usize;
    eprintln!(
        "HDEM, last second: {flips} sign changes in {steps} steps (bound {bound}); largest |ω| {largest:.2e} rad/s"
    );
    assert!(flips <= bound, "{flips} sign changes");
    assert!(
        largest < 1e-5 * SPEED / RADIUS,
        "still moving: {largest:e} rad/s"
    );
}

/// The bookkeeping balance of a rocking run closes to 1e-6 of the initial kinetic
/// energy, in 2-D and in 3-D, for both models.
#[test]
fn rocking_bookkeeping_closes() {
    for (dimension, contact) in [(2, hdem(2)), (3, hdem(3)), (2, conventional(2))] {
        let r = run(dimension, &contact, 1.0);
        let drift = r.bookkeeping_drift / r.initial_kinetic;
        let last = r.time.len() - 1;
        eprintln!(
            "{dimension}-D {}: bookkeeping drift {drift:.2e} of {:.3e} J; dissipated hysteresis {:.3e}, damping {:.3e}, slip {:.3e} J",
            if contact.contains("hdem") {
                "HDEM"
            } else {
                "conventional"
            },
            r.initial_kinetic,
            r.hysteresis[last],
            r.damping[last],
            r.slip[last]
        );
        assert!(drift < 1e-6, "drift {drift}");
    }
}

/// 3-D: a sphere rocks the same way; its HDEM frequency rises too.
#[test]
fn hdem_sphere_frequency_rises() {
    let h = run(3, &hdem(3), 2.0);
    let cycles = h.half_cycles();
    let window = rocking_window(&cycles, 0.5, 1e-3);
    let full: Vec<f64> = window
        .chunks_exact(2)
        .map(|p| 2.0 * std::f64::consts::PI / (p[1].end - p[0].start))
        .collect();
    eprintln!(
        "HDEM sphere: ω per full cycle {}",
        full.iter()
            .map(|f| format!("{f:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    assert!(full.len() >= 3);
    assert!(full[full.len() - 1] > full[0], "{full:?}");
}

/// Folder the ignored data-writing tests fill, read by the `hdem_figures` example of
/// `plugins/hdem` to draw `docs/laws/figures/hdem-*.svg`.
fn figure_data_dir() -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/hdem-figures");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the rocking time series of both models (every 10th step) and the frequency
/// of each half cycle, for the figures of `docs/laws/hdem.md`. Run once with
/// `cargo test --release --test physics -- --ignored hdem::write_rocking_figure_data`.
#[test]
#[ignore]
fn write_rocking_figure_data() {
    use std::fmt::Write as _;
    let dir = figure_data_dir();
    for (label, contact) in [("conventional", conventional(2)), ("hdem", hdem(2))] {
        let r = run(2, &contact, REST_DURATION);
        let rest = *r.angle.last().unwrap();
        let mut series = String::from("time,angle,kinetic,hysteresis,damping,slip\n");
        for k in (0..r.time.len()).step_by(10) {
            writeln!(
                series,
                "{:e},{:e},{:e},{:e},{:e},{:e}",
                r.time[k],
                r.angle[k] - rest,
                r.kinetic[k],
                r.hysteresis[k],
                r.damping[k],
                r.slip[k]
            )
            .unwrap();
        }
        std::fs::write(dir.join(format!("rocking-{label}.csv")), series).unwrap();
        let mut cycles = String::from("time,frequency,peak_spin,peak_kinetic,hysteresis,damping\n");
        for c in r.half_cycles() {
            let peak_kinetic = r.kinetic[c.first..c.last]
                .iter()
                .fold(0.0f64, |m, k| m.max(*k));
            writeln!(
                cycles,
                "{:e},{:e},{:e},{:e},{:e},{:e}",
                0.5 * (c.start + c.end),
                std::f64::consts::PI / (c.end - c.start),
                c.peak,
                peak_kinetic,
                r.hysteresis[c.last] - r.hysteresis[c.first],
                r.damping[c.last] - r.damping[c.first]
            )
            .unwrap();
        }
        std::fs::write(dir.join(format!("cycles-{label}.csv")), cycles).unwrap();
        eprintln!(
            "wrote {label}: rest at {:.3} s",
            r.rest_time(1e-4 * SPEED / RADIUS)
        );
    }
}

/// Final state of a heap run.
struct Heap {
    /// Mean angle of repose of the two flanks, degrees.
    angle: f64,
    /// Angles of the left and right flanks, degrees.
    flanks: (f64, f64),
    /// Time after which the kinetic energy stays below 1e-6 of its peak, s (`None`: it
    /// does not within the run).
    rest: Option<f64>,
    height: f64,
    kinetic_end: f64,
}

/// The heap scene with `contact` replacing its rolling part.
fn heap_scene(rolling: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hdem-heap.ron");
    let text = std::fs::read_to_string(&path).unwrap();
    let start = text
        .find("rolling: \"hdem\"")
        .expect("the scene's rolling part");
    let end = start + text[start..].find('\n').unwrap();
    format!("{}{rolling}{}", &text[..start], &text[end..])
}

/// Surface profile and angle of repose: the free surface is the top (y + r) of the
/// highest grain in bins of one largest diameter along x; each flank's angle is the
/// least-squares slope of that surface over the bins between 20 % and 80 % of the
/// heap's height (the rounded top and the single-grain toe left out), on the
/// contiguous stretch from the summit outwards down to 20 %.
fn repose_angle(grains: &[common::GrainState]) -> ((f64, f64), f64) {
    let width = 2.0 * grains.iter().fold(0.0f64, |m, g| m.max(g.radius));
    let (lo, hi) = grains
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), g| {
            (l.min(g.position.x), h.max(g.position.x))
        });
    let bins = ((hi - lo) / width).ceil() as usize + 1;
    let mut top = vec![0.0f64; bins];
    for g in grains {
        let b = ((g.position.x - lo) / width) as usize;
        top[b] = top[b].max(g.position.y + g.radius);
    }
    let height = top.iter().fold(0.0f64, |m, h| m.max(*h));
    let summit = top.iter().position(|h| *h == height).unwrap_or(0);
    // Each flank: the contiguous bins from the summit outwards down to 20 % of the
    // height (disks that rolled away from the heap's toe are not part of it), of
    // which those below 80 % are fitted.
    let fit = |outward: &mut dyn Iterator<Item = usize>| {
        let pts: Vec<(f64, f64)> = outward
            .take_while(|b| top[*b] >= 0.2 * height)
            .filter(|b| top[*b] < 0.8 * height)
            .map(|b| (lo + (b as f64 + 0.5) * width, top[b]))
            .collect();
        if pts.len() < 2 {
            return f64::NAN;
        }
        let n = pts.len() as f64;
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
        let (sxx, sxy) = pts
            .iter()
            .fold((0.0, 0.0), |(a, b), p| (a + p.0 * p.0, b + p.0 * p.1));
        let slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
        slope.abs().atan().to_degrees()
    };
    (
        (fit(&mut (0..=summit).rev()), fit(&mut (summit..bins))),
        height,
    )
}

fn heap(rolling: &str) -> Heap {
    let (mut sim, steps) = common::build(&heap_scene(rolling));
    let dt = sim.config().dt;
    let mut peak = 0.0f64;
    let mut last_above = 0.0;
    let mut kinetic = 0.0;
    for step in 1..=steps {
        sim.step().unwrap();
        kinetic = ReportSample::take(&sim.world).kinetic();
        peak = peak.max(kinetic);
        if kinetic >= 1e-6 * peak {
            last_above = step as f64 * dt;
        }
    }
    let duration = steps as f64 * dt;
    let ((left, right), height) = repose_angle(&common::grains(&mut sim));
    Heap {
        angle: 0.5 * (left + right),
        flanks: (left, right),
        rest: (last_above < duration - 10.0 * dt).then_some(last_above),
        height,
        kinetic_end: kinetic,
    }
}

/// The heap of `scenes/hdem-heap.ron` with no rolling resistance, constant torque, the
/// elastic–plastic spring–dashpot and HDEM: angle of repose and time to rest, written
/// to `target/hdem-figures/heap.csv` for the table of `docs/laws/hdem.md`. Ignored: a
/// few hundred disks for several seconds (about a minute in release).
#[test]
#[ignore]
fn heap_angle_of_repose_and_time_to_rest() {
    use std::fmt::Write as _;
    let models = [
        ("none", String::new()),
        (
            "constant_torque",
            r#"rolling: "constant_torque", rolling_friction: 0.1,"#.to_string(),
        ),
        (
            "elastic_plastic",
            r#"rolling: "elastic_plastic", rolling_friction: 0.1,"#.to_string(),
        ),
        (
            "hdem",
            r#"rolling: "hdem", rolling_friction: 0.1,"#.to_string(),
        ),
    ];
    let mut table =
        String::from("model,angle_deg,left_deg,right_deg,height_m,rest_s,kinetic_end_J\n");
    for (name, rolling) in models {
        let h = heap(&rolling);
        eprintln!(
            "{name}: angle {:.1}° (flanks {:.1}°, {:.1}°), height {:.4} m, at rest {}, final kinetic {:.2e} J",
            h.angle,
            h.flanks.0,
            h.flanks.1,
            h.height,
            h.rest.map_or("not within the run".to_string(), |t| format!(
                "after {t:.3} s"
            )),
            h.kinetic_end
        );
        writeln!(
            table,
            "{name},{:.2},{:.2},{:.2},{:.5},{},{:.3e}",
            h.angle,
            h.flanks.0,
            h.flanks.1,
            h.height,
            h.rest.map_or("-".to_string(), |t| format!("{t:.3}")),
            h.kinetic_end
        )
        .unwrap();
    }
    std::fs::write(figure_data_dir().join("heap.csv"), table).unwrap();
}

/// The demo scenes build and run: in both, each grain stops rolling and rocks (its
/// spin changes sign at least 10 times in the first second), and the HDEM grain's last
/// full rocking cycle in that second is shorter than the conventional one's.
#[test]
fn rocking_scenes_rock() {
    for (file, dimension) in [
        ("scenes/hdem-rocking.ron", 2u8),
        ("scenes/hdem-rocking-3d.ron", 3),
    ] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        let text = text.replace("duration: 4.5,", "duration: 1.0,");
        let (mut sim, steps) = common::build(&text);
        let dt = sim.config().dt;
        // Per grain (conventional first, by position): sign-change times of the spin.
        let mut crossings = [Vec::new(), Vec::new()];
        let mut previous = [0.0f64; 2];
        for step in 1..=steps {
            sim.step().unwrap();
            let mut grains = common::grains(&mut sim);
            grains.sort_by(|a, b| {
                (a.position.x + a.position.y).total_cmp(&(b.position.x + b.position.y))
            });
            for (k, g) in grains.iter().enumerate() {
                let w = rolling_spin(dimension, g.omega);
                if w * previous[k] < 0.0 {
                    crossings[k].push(step as f64 * dt);
                }
                previous[k] = w;
            }
        }
        let last_cycle = |c: &[f64]| c[c.len() - 1] - c[c.len() - 3];
        eprintln!(
            "{file}: sign changes conventional {}, HDEM {}; last full cycle {:.4} s and {:.4} s",
            crossings[0].len(),
            crossings[1].len(),
            last_cycle(&crossings[0]),
            last_cycle(&crossings[1])
        );
        assert!(
            crossings.iter().all(|c| c.len() >= 10),
            "{file}: not rocking"
        );
        assert!(
            last_cycle(&crossings[1]) < last_cycle(&crossings[0]),
            "{file}"
        );
    }
}

/// `rolling: "hdem"` without its coefficient is a scene error naming the field.
#[test]
fn hdem_without_rolling_friction_is_a_scene_error() {
    let text = scene(2, r#"rolling: "hdem""#, 0.01);
    let outcome = std::panic::catch_unwind(|| {
        talus::scene::parse("bad.ron", &text).and_then(|s| s.build(&talus::registry()).map(|_| ()))
    });
    let e = match outcome {
        Ok(Err(e)) => e,
        Ok(Ok(())) => panic!("scene was accepted"),
        Err(_) => panic!("scene handling panicked"),
    };
    eprintln!("{e}");
    assert!(e.field.ends_with("contact.rolling_friction"), "{e}");
}

/// HDEM is registered with `hertz_mindlin` too, with and without the twisting part: a
/// sphere dropped with spin onto the floor bounces, rolls and twists, and the
/// bookkeeping closes.
#[test]
fn hdem_with_hertz_mindlin_and_twisting_runs_and_balances() {
    let text = scene(3, "", 0.05)
        .replace(
            r#"(law: "linear_spring", stiffness: 1e6, restitution: 0.5, friction: 0.5, tangential_damping_ratio: 1.0, )"#,
            r#"(law: "hertz_mindlin", youngs_modulus: 1e8, poisson_ratio: 0.45, restitution: 0.5, friction: 0.5,
                rolling: "hdem", rolling_friction: 0.05, twisting: "spring_dashpot", twisting_friction: 0.3)"#,
        )
        .replace(r#"plugins: ["linear_spring"]"#, r#"plugins: ["hertz_mindlin"]"#);
    // Add a spin about the floor normal (z) to the rolling spin about y.
    let at = text
        .find("angular_velocity: (0.0, ")
        .expect("the grain's spin");
    let close = at + text[at..].find(", 0.0)").unwrap();
    let text = format!(
        "{}, 3.0){}",
        &text[..close],
        &text[close + ", 0.0)".len()..]
    );
    assert!(
        text.contains("hertz_mindlin") && text.contains(", 3.0)"),
        "{text}"
    );
    let (mut sim, steps) = common::build(&text);
    sim.prime().unwrap();
    let initial = ReportSample::take(&sim.world).kinetic();
    sim.step().unwrap();
    let first = ReportSample::take(&sim.world).bookkeeping_balance;
    let mut drift = 0.0f64;
    for _ in 1..steps {
        sim.step().unwrap();
        drift = drift.max((ReportSample::take(&sim.world).bookkeeping_balance - first).abs());
    }
    let last = ReportSample::take(&sim.world);
    eprintln!(
        "hertz_mindlin + hdem + twisting: bookkeeping drift {:.2e} of {initial:.3e} J; dissipated {:?}",
        drift / initial,
        last.dissipated
    );
    assert!(drift < 1e-6 * initial);
    assert!(last.dissipated.contains_key("rolling_hysteresis"));
}

/// With β = 1 every HDEM branch is the straight line of slope K_r and the slider is
/// the same, so the 2-D rocking run must match the elastic–plastic one step by step
/// (same K_r, ζ and μ_r): an independent check of the branch bookkeeping against the
/// incremental spring of `talus-rolling-resistance`.
#[test]
fn hdem_with_exponent_one_is_the_conventional_model() {
    let linear = format!(
        r#"rolling: "hdem", rolling_friction: {ROLLING_FRICTION}, rolling_stiffness: {:e}, rolling_damping_ratio: {CONVENTIONAL_ZETA}, hysteresis_exponent: 1.0"#,
        rolling_stiffness(2)
    );
    let (h, c) = (run(2, &linear, 1.0), run(2, &conventional(2), 1.0));
    let scale = c.spin.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let difference = h
        .spin
        .iter()
        .zip(&c.spin)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    let last = h.time.len() - 1;
    eprintln!(
        "β = 1 against elastic_plastic over 1 s: largest spin difference {:.2e} of {scale:.3e} rad/s; \
         hysteresis booked {:.2e} J; slip {:.6e} vs {:.6e} J",
        difference / scale,
        h.hysteresis[last],
        h.slip[last],
        c.slip[last]
    );
    assert!(difference < 1e-9 * scale, "spin differs by {difference}");
    assert!(h.hysteresis[last].abs() < 1e-12 * h.initial_kinetic);
}
