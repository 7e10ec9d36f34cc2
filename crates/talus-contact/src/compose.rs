//! Contact laws assembled from sub-models: normal, damping, tangential, rolling and
//! twisting parts, evaluated in that fixed order because later parts read what earlier
//! ones computed (the damping reads the normal stiffness, friction caps read the total
//! normal force, rolling resistance reads it too).
//!
//! A sub-model declares its parameters, its per-contact history, how unlike materials
//! mix (in each [`ParamSpec`]), and what it needs ([`Needs`]). [`Composed`] glues five
//! of them into one [`ContactLaw`], monomorphised, so a composed law runs as fast as one
//! written whole. [`ComposedLaw`] is its [`LawDescriptor`]: register it under the law's
//! name and scenes select it, with an optional `rolling:` and `twisting:` part.

use std::any::Any;
use std::marker::PhantomData;

use glam::DVec3;
use talus_core::energy::MAX_DISSIPATION_CHANNELS;
use talus_core::resources::Dimension;
use talus_core::schedule::SimBuilder;

use crate::kinematics::{ContactKinematics, ContactKinematicsLanes};
use crate::law::{
    ContactLaw, ContactResponse, LaneResponse, LawDescriptor, PairAssignment, TimeScale,
    install_law,
};
use crate::params::{ParamError, ParamSpec, ParamValues};
use talus_core::lanes::{F4, V4};

/// The place of a sub-model in a composed law, which is also its evaluation order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SubModelKind {
    /// Elastic normal force (Hertz, linear spring).
    Normal,
    /// Normal dissipation (dashpot).
    Damping,
    /// Cohesion or adhesion, added to the normal force (none built in yet).
    Cohesion,
    /// Tangential force (friction with or without a spring).
    Tangential,
    /// Rolling resistance torque.
    Rolling,
    /// Twisting (torsional) resistance torque.
    Twisting,
    /// Heat conduction across the contact (none built in yet).
    Heat,
}

impl SubModelKind {
    /// The word scenes use for this part (`rolling: "viscous"`).
    pub fn word(self) -> &'static str {
        match self {
            Self::Normal => "normal",
            Self::Damping => "damping",
            Self::Cohesion => "cohesion",
            Self::Tangential => "tangential",
            Self::Rolling => "rolling",
            Self::Twisting => "twisting",
            Self::Heat => "heat",
        }
    }
}

/// What a sub-model needs from the engine, for the parameters of one scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Needs {
    /// It can torque a grain, so grain rotation must be integrated.
    pub rotation: bool,
    /// It acts beyond touch, up to this gap, m (0: only while the bodies overlap).
    pub range: f64,
}

impl Needs {
    /// A part that torques grains and acts only on touch (rolling, twisting).
    pub const ROTATION: Needs = Needs {
        rotation: true,
        range: 0.0,
    };

    /// The needs of two parts together.
    pub fn union(self, other: Needs) -> Needs {
        Needs {
            rotation: self.rotation || other.rotation,
            range: self.range.max(other.range),
        }
    }
}

/// Everything the sub-models of one contact compute in one step, filled part by part.
/// The composed law turns it into a [`ContactResponse`] at the end.
#[derive(Clone, Copy, Debug, Default)]
pub struct ContactState {
    /// Elastic normal force along the normal, positive repulsive, N (from the normal part).
    pub normal_elastic: f64,
    /// Contact stiffness dF_n/dδ at the current overlap, N/m (from the normal part; the
    /// damping and tangential parts scale with it).
    pub normal_stiffness: f64,
    /// Damping normal force, N (from the damping part).
    pub normal_damping: f64,
    /// Normal dashpot coefficient c_n of this contact, N s/m (from the damping part;
    /// tangential dashpots are often a fraction of it).
    pub damping_coefficient: f64,
    /// Cohesive normal force, N (negative: attractive; from the cohesion part).
    pub normal_cohesion: f64,
    /// Tangential force on body `a`, N (from the tangential part).
    pub tangential_force: DVec3,
    /// Extra torque on `a` besides branch × force, N m (rolling, twisting).
    pub torque_a: DVec3,
    /// Extra torque on `b` besides branch × force, N m.
    pub torque_b: DVec3,
    /// Elastic energy stored after the step, J (each part adds its own).
    pub elastic_energy: f64,
    /// Energy dissipated during the step, per channel of the composed law, J.
    pub dissipated: [f64; MAX_DISSIPATION_CHANNELS],
    /// Energy created by the time integration during the step, J (each part adds its own;
    /// see [`ContactResponse::integration_error`]).
    pub integration_error: f64,
    /// First channel of the part being evaluated; set by the composed law.
    pub channel_base: usize,
}

impl ContactState {
    /// Normal force of the contact itself: elastic + damping, N (positive repulsive).
    /// Friction and rolling caps are made from it. Cohesion is left out on purpose: its
    /// pull loads the contact, which shows up as a larger elastic force (at a resting
    /// bond k_n δ = f_pull), so the cap grows with adhesion as in DMT-type models instead of
    /// vanishing where the pull balances the spring.
    #[inline]
    pub fn normal_force(&self) -> f64 {
        self.normal_elastic + self.normal_damping
    }

    /// Total normal force on body `a`: elastic + damping + cohesion, N.
    #[inline]
    pub fn total_normal_force(&self) -> f64 {
        self.normal_force() + self.normal_cohesion
    }

    /// Books `energy` on the part's own dissipation channel `k` (an index into its
    /// [`SubModel::DISSIPATION`]).
    #[inline]
    pub fn dissipate(&mut self, k: usize, energy: f64) {
        self.dissipated[self.channel_base + k] += energy;
    }
}

/// [`ContactState`] of four contacts, one per lane: what the parts' lane forms
/// ([`SubModel::evaluate_lanes`]) fill, field for field as the scalar parts fill theirs.
#[derive(Clone, Copy, Debug)]
pub struct ContactStateLanes {
    /// Elastic normal force, N.
    pub normal_elastic: F4,
    /// Contact stiffness dF_n/dδ, N/m.
    pub normal_stiffness: F4,
    /// Damping normal force, N.
    pub normal_damping: F4,
    /// Normal dashpot coefficient, N s/m.
    pub damping_coefficient: F4,
    /// Cohesive normal force, N.
    pub normal_cohesion: F4,
    /// Tangential force on body `a`, N.
    pub tangential_force: V4,
    /// Extra torque on `a`, N m.
    pub torque_a: V4,
    /// Extra torque on `b`, N m.
    pub torque_b: V4,
    /// Elastic energy stored after the step, J.
    pub elastic_energy: F4,
    /// Energy dissipated during the step, per channel of the composed law, J.
    pub dissipated: [F4; MAX_DISSIPATION_CHANNELS],
    /// Energy created by the time integration during the step, J.
    pub integration_error: F4,
    /// First channel of the part being evaluated; set by the composed law.
    pub channel_base: usize,
}

impl Default for ContactStateLanes {
    fn default() -> Self {
        Self {
            normal_elastic: F4::zero(),
            normal_stiffness: F4::zero(),
            normal_damping: F4::zero(),
            damping_coefficient: F4::zero(),
            normal_cohesion: F4::zero(),
            tangential_force: V4::zero(),
            torque_a: V4::zero(),
            torque_b: V4::zero(),
            elastic_energy: F4::zero(),
            dissipated: [F4::zero(); MAX_DISSIPATION_CHANNELS],
            integration_error: F4::zero(),
            channel_base: 0,
        }
    }
}

impl ContactStateLanes {
    /// [`ContactState::normal_force`] in lanes.
    #[inline(always)]
    pub fn normal_force(&self) -> F4 {
        self.normal_elastic + self.normal_damping
    }

    /// [`ContactState::total_normal_force`] in lanes.
    #[inline(always)]
    pub fn total_normal_force(&self) -> F4 {
        self.normal_force() + self.normal_cohesion
    }

    /// [`ContactState::dissipate`] in lanes.
    #[inline(always)]
    pub fn dissipate(&mut self, k: usize, energy: F4) {
        let channel = &mut self.dissipated[self.channel_base + k];
        *channel = *channel + energy;
    }
}

/// One part of a composed contact law.
pub trait SubModel: Send + Sync + 'static {
    /// Which part it is.
    const KIND: SubModelKind;
    /// Its name: what a scene writes after `rolling:` or `twisting:`, and what
    /// `talus check` shows.
    const NAME: &'static str;
    /// Its parameters, with units, ranges, defaults and mixing rules.
    const PARAMS: &'static [ParamSpec];
    /// Its dissipation mechanisms (report channels).
    const DISSIPATION: &'static [&'static str];
    /// Parameters resolved for one material pair.
    type Params: Clone + Send + Sync + 'static;
    /// Per-contact history, `Default` when the contact starts. Serializable so that a
    /// saved state keeps it (and, later, so that it can migrate with its grains).
    type History: Default
        + Clone
        + Send
        + Sync
        + serde::Serialize
        + serde::de::DeserializeOwned
        + 'static;

    /// Resolves the typed parameters of a pair (values are range-checked and mixed).
    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<Self::Params, ParamError>;

    /// Cross-field checks that need no pair (missing or conflicting fields).
    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        let _ = values;
        Ok(())
    }

    /// What the part needs with these parameters.
    fn needs(values: &ParamValues) -> Needs {
        let _ = values;
        Needs::default()
    }

    /// Time scales the part imposes on a pair (the normal part gives the contact time;
    /// stiff tangential or rolling springs may shorten the stability limit).
    fn time_scale(params: &Self::Params, pair: &PairAssignment) -> Option<TimeScale> {
        let _ = (params, pair);
        None
    }

    /// Evaluates the part for one contact over a step `dt` (0 in the priming pass). It
    /// is also called once in the step at which the bodies separate (overlap ≤ 0), to
    /// book the work of that step and clear its history.
    fn evaluate(
        params: &Self::Params,
        kin: &ContactKinematics,
        history: &mut Self::History,
        state: &mut ContactState,
        dt: f64,
    );

    /// Called on the normal part once the damping part has run (its force is in
    /// `state`), before cohesion and the tangential part read the normal force: a normal
    /// part whose force depends on the damping force (the linear spring's first
    /// evaluation) finishes here. Does nothing by default.
    #[inline(always)]
    fn after_damping(
        _params: &Self::Params,
        _kin: &ContactKinematics,
        _history: &mut Self::History,
        _state: &mut ContactState,
        _dt: f64,
    ) {
    }

    /// Whether the part has a lane form ([`Self::evaluate_lanes`] and, for a normal part
    /// that finishes after the damping part, [`Self::after_damping_lanes`]). A composed
    /// law has a lane form when all its parts do.
    const LANES: bool = false;

    /// [`Self::evaluate`] for four contacts at once, one per lane: the same operations in
    /// the same order, so that every lane gets the scalar form's bits (each branch a mask).
    /// All four lanes are evaluated; the composed law keeps the histories only of the lanes
    /// the core offered. With `book` false the energies are not read and may be skipped.
    /// Only called when [`Self::LANES`] is true.
    #[inline(always)]
    fn evaluate_lanes(
        params: [&Self::Params; 4],
        kin: &ContactKinematicsLanes,
        history: [&mut Self::History; 4],
        state: &mut ContactStateLanes,
        dt: f64,
        book: bool,
    ) {
        let _ = (params, kin, history, state, dt, book);
    }

    /// [`Self::after_damping`] in lanes. Does nothing by default.
    #[inline(always)]
    fn after_damping_lanes(
        params: [&Self::Params; 4],
        kin: &ContactKinematicsLanes,
        history: [&mut Self::History; 4],
        state: &mut ContactStateLanes,
        dt: f64,
        book: bool,
    ) {
        let _ = (params, kin, history, state, dt, book);
    }
}

/// The absent part: no parameters, no history, no effect.
pub struct Absent<const KIND: u8>;

/// No rolling resistance.
pub type NoRolling = Absent<4>;
/// No twisting resistance.
pub type NoTwisting = Absent<5>;
/// No damping part.
pub type NoDamping = Absent<1>;
/// No cohesion part.
pub type NoCohesion = Absent<2>;

impl<const K: u8> SubModel for Absent<K> {
    const KIND: SubModelKind = match K {
        0 => SubModelKind::Normal,
        1 => SubModelKind::Damping,
        2 => SubModelKind::Cohesion,
        3 => SubModelKind::Tangential,
        4 => SubModelKind::Rolling,
        5 => SubModelKind::Twisting,
        _ => SubModelKind::Heat,
    };
    const NAME: &'static str = "none";
    const PARAMS: &'static [ParamSpec] = &[];
    const DISSIPATION: &'static [&'static str] = &[];
    type Params = ();
    type History = ();

    fn resolve(_: &ParamValues, _: &PairAssignment) -> Result<(), ParamError> {
        Ok(())
    }

    #[inline(always)]
    fn evaluate(_: &(), _: &ContactKinematics, _: &mut (), _: &mut ContactState, _: f64) {}

    const LANES: bool = true;
}

/// A law made of a normal part `N`, a damping part `D`, a tangential part `T`, a rolling
/// part `R`, a twisting part `W` and a cohesion part `C`, evaluated in the order
/// normal → damping → cohesion → tangential → rolling → twisting (cohesion adds to the
/// normal force before the friction cap reads it).
pub struct Composed<N, D, T, R = NoRolling, W = NoTwisting, C = NoCohesion>(
    PhantomData<Parts<N, D, T, R, W, C>>,
);

/// The six parts of a composed law as a type marker (a function type: the law holds no part
/// and is `Send` and `Sync` whatever they are).
type Parts<N, D, T, R, W, C> = fn() -> (N, D, T, R, W, C);

/// Per-contact history of a composed law: one field per part.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct ComposedHistory<
    N: SubModel,
    D: SubModel,
    T: SubModel,
    R: SubModel,
    W: SubModel,
    C: SubModel,
> {
    /// Normal part's history.
    pub normal: N::History,
    /// Damping part's history.
    pub damping: D::History,
    /// Tangential part's history.
    pub tangential: T::History,
    /// Rolling part's history.
    pub rolling: R::History,
    /// Twisting part's history.
    pub twisting: W::History,
    /// Cohesion part's history.
    pub cohesion: C::History,
}

/// Parameters of a composed law for one pair: one field per part.
pub struct ComposedParams<
    N: SubModel,
    D: SubModel,
    T: SubModel,
    R: SubModel,
    W: SubModel,
    C: SubModel,
> {
    /// Normal part's parameters.
    pub normal: N::Params,
    /// Damping part's parameters.
    pub damping: D::Params,
    /// Tangential part's parameters.
    pub tangential: T::Params,
    /// Rolling part's parameters.
    pub rolling: R::Params,
    /// Twisting part's parameters.
    pub twisting: W::Params,
    /// Cohesion part's parameters.
    pub cohesion: C::Params,
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel> Default
    for ComposedHistory<N, D, T, R, W, C>
{
    fn default() -> Self {
        Self {
            normal: Default::default(),
            damping: Default::default(),
            tangential: Default::default(),
            rolling: Default::default(),
            twisting: Default::default(),
            cohesion: Default::default(),
        }
    }
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel> Clone
    for ComposedHistory<N, D, T, R, W, C>
{
    fn clone(&self) -> Self {
        Self {
            normal: self.normal.clone(),
            damping: self.damping.clone(),
            tangential: self.tangential.clone(),
            rolling: self.rolling.clone(),
            twisting: self.twisting.clone(),
            cohesion: self.cohesion.clone(),
        }
    }
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel> Clone
    for ComposedParams<N, D, T, R, W, C>
{
    fn clone(&self) -> Self {
        Self {
            normal: self.normal.clone(),
            damping: self.damping.clone(),
            tangential: self.tangential.clone(),
            rolling: self.rolling.clone(),
            twisting: self.twisting.clone(),
            cohesion: self.cohesion.clone(),
        }
    }
}

/// First dissipation channel of each part, in the order of the counts.
const fn channel_bases(counts: [usize; 6]) -> [usize; 6] {
    let mut out = [0; 6];
    let mut k = 1;
    while k < 6 {
        out[k] = out[k - 1] + counts[k - 1];
        k += 1;
    }
    out
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel>
    Composed<N, D, T, R, W, C>
{
    /// Channel bases in evaluation order: normal, damping, cohesion, tangential,
    /// rolling, twisting.
    const BASES: [usize; 6] = channel_bases([
        N::DISSIPATION.len(),
        D::DISSIPATION.len(),
        C::DISSIPATION.len(),
        T::DISSIPATION.len(),
        R::DISSIPATION.len(),
        W::DISSIPATION.len(),
    ]);

    /// The parts' declarations in evaluation order.
    const PARTS: [(
        SubModelKind,
        &'static str,
        &'static [ParamSpec],
        &'static [&'static str],
    ); 6] = [
        (N::KIND, N::NAME, N::PARAMS, N::DISSIPATION),
        (D::KIND, D::NAME, D::PARAMS, D::DISSIPATION),
        (C::KIND, C::NAME, C::PARAMS, C::DISSIPATION),
        (T::KIND, T::NAME, T::PARAMS, T::DISSIPATION),
        (R::KIND, R::NAME, R::PARAMS, R::DISSIPATION),
        (W::KIND, W::NAME, W::PARAMS, W::DISSIPATION),
    ];

    /// Dissipation channels of the composed law, part by part.
    pub fn channels() -> Vec<&'static str> {
        Self::PARTS
            .iter()
            .flat_map(|p| p.3.iter().copied())
            .collect()
    }

    /// Declared parameters of all parts, first declaration of a name winning.
    pub fn params() -> Vec<ParamSpec> {
        let mut out: Vec<ParamSpec> = Vec::new();
        for part in Self::PARTS {
            for s in part.2 {
                if !out.iter().any(|o| o.name == s.name) {
                    out.push(*s);
                }
            }
        }
        out
    }
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel> ContactLaw
    for Composed<N, D, T, R, W, C>
{
    type Params = ComposedParams<N, D, T, R, W, C>;
    type History = ComposedHistory<N, D, T, R, W, C>;

    fn dissipation() -> Vec<&'static str> {
        Self::channels()
    }

    #[inline]
    fn evaluate(
        p: &Self::Params,
        kin: &ContactKinematics,
        h: &mut Self::History,
        dt: f64,
    ) -> ContactResponse {
        let mut s = ContactState::default();
        let b = Self::BASES;
        s.channel_base = b[0];
        N::evaluate(&p.normal, kin, &mut h.normal, &mut s, dt);
        s.channel_base = b[1];
        D::evaluate(&p.damping, kin, &mut h.damping, &mut s, dt);
        N::after_damping(&p.normal, kin, &mut h.normal, &mut s, dt);
        s.channel_base = b[2];
        C::evaluate(&p.cohesion, kin, &mut h.cohesion, &mut s, dt);
        s.channel_base = b[3];
        T::evaluate(&p.tangential, kin, &mut h.tangential, &mut s, dt);
        s.channel_base = b[4];
        R::evaluate(&p.rolling, kin, &mut h.rolling, &mut s, dt);
        s.channel_base = b[5];
        W::evaluate(&p.twisting, kin, &mut h.twisting, &mut s, dt);
        ContactResponse {
            force: kin.normal * s.total_normal_force() + s.tangential_force,
            torque_a: s.torque_a,
            torque_b: s.torque_b,
            elastic_energy: s.elastic_energy,
            dissipated: s.dissipated,
            integration_error: s.integration_error,
        }
    }

    const LANES: bool = N::LANES && D::LANES && T::LANES && R::LANES && W::LANES && C::LANES;

    #[inline(always)]
    fn evaluate_lanes(
        p: [&Self::Params; 4],
        kin: &ContactKinematicsLanes,
        history: [&mut Self::History; 4],
        lanes: u32,
        dt: f64,
        book: bool,
    ) -> (u32, LaneResponse) {
        if !Self::LANES || lanes == 0 {
            return (0, LaneResponse::default());
        }
        let mut s = ContactStateLanes::default();
        let b = Self::BASES;
        let mut run = |[h0, h1, h2, h3]: [&mut Self::History; 4]| {
            macro_rules! part {
                ($field:ident) => {
                    (
                        [&p[0].$field, &p[1].$field, &p[2].$field, &p[3].$field],
                        [
                            &mut h0.$field,
                            &mut h1.$field,
                            &mut h2.$field,
                            &mut h3.$field,
                        ],
                    )
                };
            }
            s.channel_base = b[0];
            let (pp, hh) = part!(normal);
            N::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
            s.channel_base = b[1];
            let (pp, hh) = part!(damping);
            D::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
            let (pp, hh) = part!(normal);
            N::after_damping_lanes(pp, kin, hh, &mut s, dt, book);
            s.channel_base = b[2];
            let (pp, hh) = part!(cohesion);
            C::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
            s.channel_base = b[3];
            let (pp, hh) = part!(tangential);
            T::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
            s.channel_base = b[4];
            let (pp, hh) = part!(rolling);
            R::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
            s.channel_base = b[5];
            let (pp, hh) = part!(twisting);
            W::evaluate_lanes(pp, kin, hh, &mut s, dt, book);
        };
        if lanes == 0xF {
            run(history);
        } else {
            // The parts evaluate all four lanes, here on copies; only the offered lanes
            // keep theirs.
            let mut local: [Self::History; 4] = std::array::from_fn(|l| history[l].clone());
            run(local.each_mut());
            for (l, (h, new)) in history.into_iter().zip(local).enumerate() {
                if lanes >> l & 1 == 1 {
                    *h = new;
                }
            }
        }
        let response = LaneResponse {
            force: kin.normal * s.total_normal_force() + s.tangential_force,
            torque_a: s.torque_a,
            torque_b: s.torque_b,
            elastic_energy: s.elastic_energy,
            dissipated: s.dissipated,
            integration_error: s.integration_error,
        };
        (lanes, response)
    }
}

/// The descriptor of a composed law: what scenes see of it. The law is selected by its
/// name; its rolling and twisting parts (named by `R` and `W`) by `rolling:` and
/// `twisting:`. Register one descriptor per combination a scene may pick.
pub struct ComposedLaw<N, D, T, R = NoRolling, W = NoTwisting, C = NoCohesion> {
    name: &'static str,
    label: &'static str,
    summary: &'static str,
    params: Vec<ParamSpec>,
    _parts: PhantomData<Parts<N, D, T, R, W, C>>,
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel>
    ComposedLaw<N, D, T, R, W, C>
{
    /// A composed law named `name` (its rolling and twisting parts are named by `R` and `W`).
    pub fn new(name: &'static str, summary: &'static str) -> Self {
        assert_eq!(
            N::KIND,
            SubModelKind::Normal,
            "{}: first part must be normal",
            N::NAME
        );
        assert_eq!(
            D::KIND,
            SubModelKind::Damping,
            "{}: second part must be damping",
            D::NAME
        );
        assert_eq!(
            T::KIND,
            SubModelKind::Tangential,
            "{}: third part must be tangential",
            T::NAME
        );
        assert_eq!(
            R::KIND,
            SubModelKind::Rolling,
            "{}: fourth part must be rolling",
            R::NAME
        );
        assert_eq!(
            W::KIND,
            SubModelKind::Twisting,
            "{}: fifth part must be twisting",
            W::NAME
        );
        assert_eq!(
            C::KIND,
            SubModelKind::Cohesion,
            "{}: sixth part must be cohesion",
            C::NAME
        );
        assert!(
            Composed::<N, D, T, R, W, C>::channels().len() <= MAX_DISSIPATION_CHANNELS,
            "{name}: more than {MAX_DISSIPATION_CHANNELS} dissipation channels"
        );
        let mut label = name.to_string();
        for (word, part) in [
            ("rolling", part_name::<R>()),
            ("twisting", part_name::<W>()),
        ] {
            if let Some(part) = part {
                label.push_str(&format!("+{word}:{part}"));
            }
        }
        Self {
            name,
            // Registered once per program; the label names the law's systems.
            label: Box::leak(label.into_boxed_str()),
            summary,
            params: Composed::<N, D, T, R, W, C>::params(),
            _parts: PhantomData,
        }
    }

    fn needs(values: &ParamValues) -> Needs {
        N::needs(values)
            .union(D::needs(values))
            .union(T::needs(values))
            .union(R::needs(values))
            .union(W::needs(values))
            .union(C::needs(values))
    }
}

/// Name of an optional part for [`LawDescriptor::rolling`] and [`LawDescriptor::twisting`].
fn part_name<P: SubModel>() -> Option<&'static str> {
    (P::NAME != "none").then_some(P::NAME)
}

impl<N: SubModel, D: SubModel, T: SubModel, R: SubModel, W: SubModel, C: SubModel> LawDescriptor
    for ComposedLaw<N, D, T, R, W, C>
{
    fn name(&self) -> &'static str {
        self.name
    }

    fn summary(&self) -> &'static str {
        self.summary
    }

    fn parts(&self) -> Vec<(SubModelKind, &'static str)> {
        Composed::<N, D, T, R, W, C>::PARTS
            .iter()
            .filter(|p| p.1 != "none")
            .map(|p| (p.0, p.1))
            .collect()
    }

    fn rolling(&self) -> Option<&'static str> {
        part_name::<R>()
    }

    fn twisting(&self) -> Option<&'static str> {
        part_name::<W>()
    }

    fn params(&self) -> &[ParamSpec] {
        &self.params
    }

    fn validate(&self, values: &ParamValues) -> Result<(), ParamError> {
        N::validate(values)?;
        D::validate(values)?;
        T::validate(values)?;
        R::validate(values)?;
        W::validate(values)?;
        C::validate(values)
    }

    fn produces_torque(&self, values: &ParamValues) -> bool {
        Self::needs(values).rotation
    }

    fn interaction_range(&self, values: &ParamValues) -> f64 {
        Self::needs(values).range
    }

    fn resolve(
        &self,
        pair: &PairAssignment,
    ) -> Result<(Box<dyn Any + Send + Sync>, TimeScale), ParamError> {
        let v = &pair.values;
        let p = ComposedParams::<N, D, T, R, W, C> {
            normal: N::resolve(v, pair)?,
            damping: D::resolve(v, pair)?,
            tangential: T::resolve(v, pair)?,
            rolling: R::resolve(v, pair)?,
            twisting: W::resolve(v, pair)?,
            cohesion: C::resolve(v, pair)?,
        };
        let scales = [
            N::time_scale(&p.normal, pair),
            D::time_scale(&p.damping, pair),
            T::time_scale(&p.tangential, pair),
            R::time_scale(&p.rolling, pair),
            W::time_scale(&p.twisting, pair),
            C::time_scale(&p.cohesion, pair),
        ];
        let mut ts: Option<TimeScale> = None;
        for s in scales.into_iter().flatten() {
            ts = Some(match ts {
                None => s,
                Some(t) => TimeScale {
                    contact_time: t.contact_time.min(s.contact_time),
                    stability_limit: t.stability_limit.min(s.stability_limit),
                },
            });
        }
        let ts = ts.ok_or_else(|| ParamError {
            field: "law".into(),
            expected: format!(
                "a law whose parts give a contact time (`{}` gives none)",
                self.name
            ),
        })?;
        Ok((Box::new(p), ts))
    }

    fn install(
        &self,
        sim: &mut SimBuilder,
        pairs: &[(PairAssignment, Box<dyn Any + Send + Sync>)],
    ) {
        install_law::<Composed<N, D, T, R, W, C>>(sim, self.label, pairs);
    }
}

/// Whether a pair's contacts are two-dimensional (disks): sub-models that differ between
/// disks and spheres read it from the pair.
pub fn is_two_dimensional(pair: &PairAssignment) -> bool {
    pair.dimension == Dimension::Two
}
