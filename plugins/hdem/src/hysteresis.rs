//! The scalar hysteresis spring of seed 001 (eqs. (11)–(13)): loading and unloading
//! branches anchored at the last reversal point, with a slider at the elastic limit.
//!
//! Sign convention: the deformation Δ (rad) is the rolling rotation of body `a`
//! relative to `b` along the element's axis, and M (N m) is the spring moment, of the
//! sign of Δ; the torque on `a` is −M along the axis.
//!
//! Every branch has the same form. From its start (Δ_s, M_s) towards its target
//! (Δ_t, M_t), with u = |Δ − Δ_s| the distance run along it, L = |Δ_t − Δ_s| and
//! A = |M_t − M_s|:
//!
//!   M = M_s + sgn(M_t − M_s) g(u),   g(u) = min(K̂ u, A (u/L)^β).
//!
//! * Loading (away from the origin): target (±Δ_e, ±M_e), the elastic limit; from the
//!   origin this is eq. (13), M = M_e (Δ/Δ_e)^β. Eq. (11) as printed is linear; this
//!   element uses the same power β from any reversal point (see `docs/laws/hdem.md` for
//!   why: (13) is stated to be (11) at Δ_rev = 0, which only holds with the power).
//! * Unloading (towards the origin): target (0, 0); g(u) = |M_rev| (u/|Δ_rev|)^β is
//!   eq. (12), M = M_rev [1 − (1 − Δ/Δ_rev)^β].
//!
//! The power law has an infinite slope where a branch starts; the ceiling K̂ (the
//! `hysteresis_stiffness_ceiling` times K_r, and never below the branch's secant A/L)
//! caps it, so that the explicit integration stays stable and small oscillations keep
//! a finite frequency. A loading branch that reaches its target slides (the slider of
//! the model): Δ stays at the elastic limit and the slider works at M_e.

/// Constants of the element for one contact and step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HysteresisLimits {
    /// Reference stiffness K_r = M_e/Δ_e, N m/rad: the secant of the first loading
    /// branch, and the stiffness the identification K_r = ω² J_z gives.
    pub stiffness: f64,
    /// Elastic-limit moment M_e = μ_r F_n R*, N m (the slider's limit).
    pub limit_moment: f64,
    /// Exponent β of eqs. (12)–(13), in (0, 1]; β = 1 is the linear spring.
    pub exponent: f64,
    /// Largest tangent stiffness of a branch, N m/rad (raised to the branch's secant
    /// when that is larger).
    pub stiffness_ceiling: f64,
}

impl HysteresisLimits {
    /// Elastic-limit deformation Δ_e = M_e / K_r, rad (0 without a valid stiffness).
    #[inline]
    pub fn limit_deformation(&self) -> f64 {
        if self.stiffness > 0.0 && self.stiffness.is_finite() {
            self.limit_moment / self.stiffness
        } else {
            0.0
        }
    }
}

/// Which branch the element is on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Branch {
    /// Unloaded, at the origin, no branch yet.
    #[default]
    Rest,
    /// Moving away from the origin towards the elastic limit (eqs. (11), (13)).
    Loading,
    /// Moving back towards the origin (eq. (12)).
    Unloading,
}

/// State of one hysteresis spring.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HysteresisState {
    /// Deformation Δ, rad.
    pub deformation: f64,
    /// Current branch.
    pub branch: Branch,
    /// Deformation at the start of the branch (the last reversal point), rad.
    pub start_deformation: f64,
    /// Moment at the start of the branch, N m.
    pub start_moment: f64,
    /// +1 or −1: the sign of dΔ along the branch.
    pub direction: f64,
}

/// What one [`HysteresisState::advance`] did, J.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HysteresisStep {
    /// Exact work ∫ M dΔ done on the spring along its branches (the slider excluded).
    pub branch_work: f64,
    /// Work dissipated by the slider, M_e times the rotation it let slip.
    pub slip: f64,
    /// Whether the slider slid during the step.
    pub sliding: bool,
}

/// The shape of one branch: amplitude A (N m), length L (rad), ceiling K̂ (N m/rad) and
/// exponent β.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchShape {
    /// |M_t − M_s|, N m.
    pub amplitude: f64,
    /// |Δ_t − Δ_s|, rad.
    pub length: f64,
    /// Tangent-stiffness ceiling, at least the secant A/L, N m/rad.
    pub ceiling: f64,
    /// Exponent β.
    pub exponent: f64,
}

impl BranchShape {
    /// A branch of amplitude `amplitude` over `length`, with the ceiling raised to the
    /// secant if needed (so that the branch still ends at its target).
    #[inline]
    pub fn new(amplitude: f64, length: f64, ceiling: f64, exponent: f64) -> Self {
        let amplitude = amplitude.max(0.0);
        let length = length.max(0.0);
        let secant = if length > 0.0 {
            amplitude / length
        } else {
            0.0
        };
        Self {
            amplitude,
            length,
            ceiling: ceiling.max(secant),
            exponent,
        }
    }

    /// Whether the branch has room to move along (a positive length and amplitude).
    #[inline]
    fn is_open(&self) -> bool {
        self.length > 0.0 && self.amplitude > 0.0
    }

    /// Where the ceiling K̂ u meets the power law A (u/L)^β, rad (0 for β = 1, where
    /// the branch is straight at its secant).
    #[inline]
    pub fn crossover(&self) -> f64 {
        if !self.is_open() || self.exponent >= 1.0 {
            return 0.0;
        }
        let ratio = self.amplitude / (self.ceiling * self.length);
        self.length * ratio.powf(1.0 / (1.0 - self.exponent))
    }

    /// Moment change g(u) after running `u` along the branch, N m.
    #[inline]
    pub fn rise(&self, u: f64) -> f64 {
        if !self.is_open() {
            return self.amplitude;
        }
        let u = u.clamp(0.0, self.length);
        (self.ceiling * u).min(self.amplitude * (u / self.length).powf(self.exponent))
    }

    /// ∫₀ᵘ g, J: the work of the branch's moment change over the first `u` of it.
    #[inline]
    pub fn rise_integral(&self, u: f64) -> f64 {
        if !self.is_open() {
            return 0.0;
        }
        let u = u.clamp(0.0, self.length);
        let uc = self.crossover().min(self.length);
        if u <= uc {
            return 0.5 * self.ceiling * u * u;
        }
        let p = 1.0 + self.exponent;
        0.5 * self.ceiling * uc * uc
            + self.amplitude * self.length / p
                * ((u / self.length).powf(p) - (uc / self.length).powf(p))
    }
}

/// Sign of `x` as ±1 (+1 for zero).
#[inline]
fn sign(x: f64) -> f64 {
    if x < 0.0 { -1.0 } else { 1.0 }
}

impl HysteresisState {
    /// Target (Δ_t, M_t) of the current branch.
    #[inline]
    fn target(&self, limits: &HysteresisLimits) -> (f64, f64) {
        match self.branch {
            Branch::Unloading | Branch::Rest => (0.0, 0.0),
            Branch::Loading => (
                self.direction * limits.limit_deformation(),
                self.direction * limits.limit_moment,
            ),
        }
    }

    /// Shape of the current branch.
    #[inline]
    fn shape(&self, limits: &HysteresisLimits) -> BranchShape {
        let (dt, mt) = self.target(limits);
        BranchShape::new(
            self.direction * (mt - self.start_moment),
            self.direction * (dt - self.start_deformation),
            limits.stiffness_ceiling,
            limits.exponent,
        )
    }

    /// Distance run along the current branch, rad.
    #[inline]
    fn run(&self) -> f64 {
        (self.direction * (self.deformation - self.start_deformation)).max(0.0)
    }

    /// The spring moment M, N m.
    #[inline]
    pub fn moment(&self, limits: &HysteresisLimits) -> f64 {
        match self.branch {
            Branch::Rest => 0.0,
            _ => {
                let shape = self.shape(limits);
                if !shape.is_open() {
                    // At (or past) the target: the slider holds the limit.
                    return self.target(limits).1;
                }
                self.start_moment + self.direction * shape.rise(self.run())
            }
        }
    }

    /// Recoverable energy, J: what the spring would give back if unloaded from here to
    /// the origin (along the current unloading branch, or along the eq.-(12) branch a
    /// reversal here would start).
    pub fn recoverable_energy(&self, limits: &HysteresisLimits) -> f64 {
        match self.branch {
            Branch::Rest => 0.0,
            Branch::Unloading => {
                let shape = self.shape(limits);
                let u = self.run().min(shape.length);
                (shape.amplitude * (shape.length - u)
                    - (shape.rise_integral(shape.length) - shape.rise_integral(u)))
                .max(0.0)
            }
            Branch::Loading => {
                let m = self.moment(limits);
                let d = self.deformation;
                if m * d <= 0.0 {
                    return 0.0;
                }
                let shape =
                    BranchShape::new(m.abs(), d.abs(), limits.stiffness_ceiling, limits.exponent);
                (m.abs() * d.abs() - shape.rise_integral(d.abs())).max(0.0)
            }
        }
    }

    /// Starts a new branch at the current point in direction `direction`: unloading if
    /// the origin lies ahead, loading otherwise.
    #[inline]
    fn reverse(&mut self, direction: f64, limits: &HysteresisLimits) {
        let moment = self.moment(limits);
        self.start_deformation = self.deformation;
        self.start_moment = moment;
        self.direction = direction;
        self.branch = if self.deformation * direction < 0.0 && moment * direction < 0.0 {
            Branch::Unloading
        } else {
            Branch::Loading
        };
    }

    /// Moves the deformation by `increment` (rad) along the branches, switching branch
    /// at reversals, at the origin and at the elastic limit. Returns the exact work done
    /// on the spring and the slider's dissipation. A non-finite increment is ignored.
    pub fn advance(&mut self, increment: f64, limits: &HysteresisLimits) -> HysteresisStep {
        let mut out = HysteresisStep::default();
        if !increment.is_finite() || increment == 0.0 {
            return out;
        }
        let direction = sign(increment);
        if self.branch == Branch::Rest {
            *self = HysteresisState {
                deformation: self.deformation,
                branch: Branch::Loading,
                start_deformation: self.deformation,
                start_moment: 0.0,
                direction,
            };
        } else if self.direction != direction {
            self.reverse(direction, limits);
        }
        let mut remaining = increment.abs();
        // At most: finish an unloading branch, cross the origin, reach the limit, slide.
        for _ in 0..4 {
            if remaining <= 0.0 {
                break;
            }
            let shape = self.shape(limits);
            let u = self.run();
            let room = shape.length - u;
            if room >= remaining {
                let u_new = u + remaining;
                out.branch_work += self.direction * self.start_moment * remaining
                    + shape.rise_integral(u_new)
                    - shape.rise_integral(u);
                self.deformation += self.direction * remaining;
                break;
            }
            // The branch ends within the step (or has already ended: room ≤ 0).
            let room = room.max(0.0);
            out.branch_work += self.direction * self.start_moment * room
                + shape.rise_integral(shape.length)
                - shape.rise_integral(u.min(shape.length));
            remaining -= room;
            let (target_deformation, target_moment) = self.target(limits);
            self.deformation = target_deformation;
            match self.branch {
                Branch::Unloading => {
                    // Through the origin: the opposite loading branch, eq. (13).
                    self.branch = Branch::Loading;
                    self.start_deformation = 0.0;
                    self.start_moment = 0.0;
                    self.deformation = 0.0;
                }
                _ => {
                    // At the elastic limit: the slider takes the rest of the rotation.
                    out.slip += target_moment.abs() * remaining;
                    out.sliding = true;
                    break;
                }
            }
        }
        out
    }
}

/// Energy lost in one closed symmetric loop of amplitude `amplitude` (rad) of a spring
/// whose first loading reached (±A, ±M_A), computed from eqs. (12)–(13) without the
/// stiffness ceiling: each half loop takes in ∫₀ᴬ M_e (Δ/Δ_e)^β dΔ = M_A A/(1+β) and
/// gives back ∫₀ᴬ M_A [1 − (1 − Δ/A)^β] dΔ = β M_A A/(1+β), so the loop loses
/// 2 (1 − β)/(1 + β) M_A A with M_A = M_e (A/Δ_e)^β. Valid for A ≤ Δ_e.
pub fn loop_loss(limits: &HysteresisLimits, amplitude: f64) -> f64 {
    let de = limits.limit_deformation();
    if de <= 0.0 {
        return 0.0;
    }
    let beta = limits.exponent;
    let moment = limits.limit_moment * (amplitude.abs() / de).powf(beta);
    2.0 * (1.0 - beta) / (1.0 + beta) * moment * amplitude.abs()
}
