//! Asymmetric Bouc-Wen hysteresis, seed 001 eq. (3)-(4).
//!
//! Seed 001 writes the hysteretic state as
//!
//! ```text
//! ḣ = A·u̇ − β·|u̇|·|h|^(n−1)·h − γ·u̇·|h|^n + Δε,   Δε = δ·u·sgn(u̇)      (eq. 3)
//! y = p·u + q·h                                                      (eq. 4)
//! ```
//!
//! Taken literally, the asymmetry term Δε does not scale with |u̇|: h would keep
//! changing while the input creeps, a slower sweep would trace a different loop
//! and a held input would still move h. Hysteresis in a piezo stack is (to first
//! order) rate independent, and seed 001 identifies the model on loops, so this
//! crate reads the term as Δε = δ·u·u̇, i.e. the printed term times |u̇|. Every
//! term of ḣ is then proportional to u̇, time drops out, and h is a function of
//! the input path alone:
//!
//! ```text
//! dh/du = A − β·sgn(du)·|h|^(n−1)·h − γ·|h|^n + δ·u
//! ```
//!
//! The state is therefore integrated in u, not in time, with classical RK4 along
//! the straight input path from the last input to the new one (sgn(du) is
//! constant along such a path), in substeps of at most `max_du`.
//!
//! Units in this project: u in volts (actuator voltage, 0..100 V), y and h in µm;
//! p [µm/V], q [1], A [µm/V], β and γ [µm^(1−n)/V], δ [µm/V²].

use crate::parameter::{ParamError, Range, RealParameter};
use arrayvec::ArrayVec;
use serde::{Deserialize, Serialize};

/// Parameters of the asymmetric Bouc-Wen model (seed 001 eq. (3)-(4)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoucWenParams {
    /// Linear gain of the input in the output, eq. (4) [µm/V].
    pub p: f64,
    /// Weight of the hysteretic state in the output, eq. (4) [1].
    pub q: f64,
    /// Input gain of the hysteretic state, eq. (3) [µm/V].
    pub a: f64,
    /// Direction-dependent (dissipative) shape coefficient, eq. (3) [µm^(1−n)/V].
    pub beta: f64,
    /// Direction-independent shape coefficient, eq. (3) [µm^(1−n)/V].
    pub gamma: f64,
    /// Exponent controlling the sharpness of the branch transitions, eq. (3) [1], n ≥ 1.
    pub n: f64,
    /// Asymmetry coefficient of Δε, eq. (3), read rate-independently [µm/V²].
    pub delta: f64,
}

/// The citation key of seed 001 in shipped descriptions ("A modified
/// asymmetric Bouc-Wen model-based decoupling control of an XY
/// piezoactuated compliant platform with coupled hysteresis
/// characteristics"); the FMUs' documentation lists it in full.
macro_rules! cite {
    ($equation:literal) => {
        concat!("(ABW-XY eq. ", $equation, ")")
    };
}

impl BoucWenParams {
    /// The seven parameters of eq. (3)-(4), in the order the FMUs list them:
    /// field, symbol, unit, range and meaning, read by [`Self::validate`] and
    /// by the FMUs' variable tables.
    pub const PARAMETERS: [RealParameter<BoucWenParams>; 7] = [
        RealParameter {
            field: "p",
            symbol: "p",
            unit: "um/V",
            range: Range::FINITE,
            description: concat!(
                "p, gain of the input u in the output y = p·u + q·h ",
                cite!("4")
            ),
            get: |m| m.p,
            set: |m, v| m.p = v,
        },
        RealParameter {
            field: "q",
            symbol: "q",
            unit: "",
            range: Range::FINITE,
            description: concat!(
                "q, weight of the hysteretic state h in the output y = p·u + q·h ",
                cite!("4")
            ),
            get: |m| m.q,
            set: |m, v| m.q = v,
        },
        RealParameter {
            field: "a",
            symbol: "A",
            unit: "um/V",
            range: Range::FINITE,
            description: concat!(
                "A, input gain of the hysteretic state (growth of h per volt) ",
                cite!("3")
            ),
            get: |m| m.a,
            set: |m, v| m.a = v,
        },
        RealParameter {
            field: "beta",
            symbol: "beta",
            unit: "",
            range: Range::FINITE,
            description: concat!(
                "beta, direction-dependent (dissipative) shape coefficient [um^(1-n)/V] ",
                cite!("3")
            ),
            get: |m| m.beta,
            set: |m, v| m.beta = v,
        },
        RealParameter {
            field: "gamma",
            symbol: "gamma",
            unit: "",
            range: Range::FINITE,
            description: concat!(
                "gamma, direction-independent shape coefficient [um^(1-n)/V] ",
                cite!("3")
            ),
            get: |m| m.gamma,
            set: |m, v| m.gamma = v,
        },
        // |h|^(n−1) must stay finite at h = 0.
        RealParameter {
            field: "n",
            symbol: "n",
            unit: "",
            range: Range::at_least(1.0),
            description: concat!(
                "n, sharpness of the branch transitions, n >= 1 ",
                cite!("3")
            ),
            get: |m| m.n,
            set: |m, v| m.n = v,
        },
        RealParameter {
            field: "delta",
            symbol: "delta",
            unit: "um/V2",
            range: Range::FINITE,
            description: concat!(
                "delta, asymmetry coefficient, read rate-independently as delta·u·du/dt ",
                cite!("3")
            ),
            get: |m| m.delta,
            set: |m, v| m.delta = v,
        },
    ];

    /// Checks every parameter against [`Self::PARAMETERS`]; `prefix` is the
    /// serde path of this model in the error.
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        Self::PARAMETERS
            .iter()
            .try_for_each(|parameter| parameter.check(prefix, self))
    }

    /// Refuses a model whose hysteretic state runs away between `low` and
    /// `high` [V], each held within ±1 kV (`range` says what they are, for
    /// the message): from the
    /// virgin state, up to `high`, down to `low` and up again, in substeps of
    /// 0.1 V (the rest cycle's). Each parameter inside its own range can still
    /// make eq. (3) run away (beta + gamma < 0 steepens the loading branch as
    /// h grows, without bound for n > 1); a model built on such parameters
    /// turns non-finite at its first large input, so the error, on `beta` or
    /// `gamma` of `prefix` (the negative one), says so before any run.
    pub fn check_bounded(
        &self,
        prefix: &str,
        low: f64,
        high: f64,
        range: &str,
    ) -> Result<(), ParamError> {
        const SUBSTEP: f64 = 0.1;
        // |h| beyond 1 m of displacement is no actuator's state.
        const BOUND: f64 = 1e6;
        // No piezo amplifier drives a stack past 1 kV, and an absurd range is
        // not integrated for seconds at every build; a run beyond it is still
        // watched step by step.
        const LIMIT: f64 = 1000.0;
        let (low, high) = (low.max(-LIMIT), high.min(LIMIT));
        let mut model = AsymmetricBoucWen::new(*self);
        for end in [high, low, high] {
            model.advance_to(end, SUBSTEP);
            let h = model.hysteretic_state();
            if !(h.is_finite() && h.abs() <= BOUND) {
                let sum = self.beta + self.gamma;
                // The negative one of the two is the likelier slip.
                let (field, value) = if self.beta < 0.0 && self.gamma >= 0.0 {
                    ("beta", self.beta)
                } else {
                    ("gamma", self.gamma)
                };
                return Err(ParamError {
                    parameter: format!("{prefix}.{field}"),
                    value,
                    allowed: format!(
                        "a Bouc-Wen model whose hysteretic state stays finite over {range} \
                         {low}..{high} V; with beta = {}, gamma = {} (beta + gamma = {sum}) and \
                         n = {}, its h runs away on the way to {end} V{}",
                        self.beta,
                        self.gamma,
                        self.n,
                        if sum < 0.0 {
                            " (beta + gamma < 0 steepens the loading branch as h grows)"
                        } else {
                            ""
                        }
                    ),
                });
            }
        }
        Ok(())
    }

    /// dh/du of eq. (3) (this module's reading) at input `u`, state `h`, for
    /// an input moving in the direction of `direction` (its sign).
    pub fn state_slope(&self, u: f64, h: f64, direction: f64) -> f64 {
        let abs_h = h.abs();
        let pow = if self.n == 1.0 {
            1.0
        } else {
            abs_h.powf(self.n - 1.0)
        };
        self.a - self.beta * direction.signum() * pow * h - self.gamma * pow * abs_h
            + self.delta * u
    }

    /// The model of the map u' ↦ H[g·u']: the same actuator seen from an
    /// input `g` times smaller (e.g. amplifier volts to command volts through
    /// an amplifier of gain g). From eq. (3) with du = g·du':
    /// p' = g·p, A' = g·A, β' = g·β, γ' = g·γ, δ' = g²·δ.
    pub fn with_input_scale(&self, g: f64) -> BoucWenParams {
        BoucWenParams {
            p: self.p * g,
            q: self.q,
            a: self.a * g,
            beta: self.beta * g,
            gamma: self.gamma * g,
            n: self.n,
            delta: self.delta * g * g,
        }
    }

    /// The same input-output map with the hysteretic state scaled by `s > 0`
    /// (h' = s·h). Eq. (3)-(4) hold one redundant degree of freedom: with
    ///
    /// ```text
    /// q' = q/s,  A' = s·A,  β' = β·s^(1−n),  γ' = γ·s^(1−n),  δ' = s·δ
    /// ```
    ///
    /// h' obeys eq. (3) with the primed parameters and q'·h' = q·h, so no
    /// record can tell the two sets apart. Identification therefore fixes one
    /// of them (see `piezo-identify`'s Bouc-Wen fit) and comparisons of
    /// parameter sets first bring them to a common scale.
    pub fn with_state_scale(&self, s: f64) -> BoucWenParams {
        let shape = s.powf(1.0 - self.n);
        BoucWenParams {
            p: self.p,
            q: self.q / s,
            a: self.a * s,
            beta: self.beta * shape,
            gamma: self.gamma * shape,
            n: self.n,
            delta: self.delta * s,
        }
    }
}

/// Largest input substep used by [`simulate`] [V]: the RK4 error per volt is then
/// far below a picometre for the loop shapes of this project (memory lengths of
/// tens of volts).
pub const SIMULATE_MAX_DU: f64 = 0.01;

/// Most RK4 substeps one [`AsymmetricBoucWen::advance_to`] takes. A path this
/// long in `max_du` substeps (1,000 V at [`SIMULATE_MAX_DU`], ten times any
/// actuator's range) only comes from inputs no actuator sees, such as the
/// trial voltages of an inverse model asked for an unreachable output; beyond
/// it the substeps grow, bounding the time of a call (about 10 ms) instead of
/// its accuracy.
pub const MAX_SUBSTEPS: usize = 100_000;

/// Input steps per half cycle of the cycles that find an exercised rest: the
/// step is 0.1 % of the cycle (0.1 V for a 100 V loop), where RK4 is exact to
/// far below a picometre on any branch whose memory spans a few percent of
/// the loop or more, and a model in command volts (input 10 times smaller,
/// shape coefficients 10 times larger) takes the same steps along its loop.
const REST_CYCLE_STEPS: f64 = 1000.0;
/// Most cycles [`AsymmetricBoucWen::at_exercised_rest`] runs; every loop of
/// this project settles to 1e-12 µm within ten.
const REST_CYCLES: usize = 50;

/// Where a model rests at u = 0 and what its output reads there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RestState {
    /// Hysteretic state at rest [µm].
    pub h: f64,
    /// eq. (4)'s output at rest, subtracted from [`AsymmetricBoucWen::output`]
    /// so that the output reads 0 at rest [µm].
    pub offset: f64,
}

/// Most reversals a [`ReturnPointMemory`] holds. Sensor noise fed back to a
/// held stack makes its voltage reverse at almost every sample, but each new
/// extreme beyond an older one wipes that one out, so the nested reversals
/// left stand in a few tens at most (a test dithers a stack for 100,000
/// reversals, uniform in ±0.025 V, and counts 26 at most). A full memory
/// forgets its two oldest reversals, whose loops are the largest and the
/// longest ago.
pub const MEMORY_CAPACITY: usize = 64;

/// A reversal of the input that a [`ReturnPointMemory`] remembers: where the
/// input turned, the hysteretic state there, and the tilt of the branch that
/// left it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Reversal {
    /// Input where the input turned [V].
    pub u: f64,
    /// Hysteretic state there [µm].
    pub h: f64,
    /// Slope added to eq. (3)'s along the branch that leaves this reversal,
    /// so that the branch ends at the reversal before it [µm/V].
    pub tilt: f64,
}

/// The return-point memory that closes a Bouc-Wen model's minor loops.
///
/// Seed 001's eq. (3) has none: a branch that turns back at u_b does not, in
/// general, pass through the point (u_a, h_a) where the branch it left
/// began, so a loop between u_a and u_b drifts onto an attractor over many
/// cycles, and dither ratchets the state (MODEL.md §6). A real stack's minor
/// loops close and an excursion beyond a past reversal continues the branch
/// that led there (return-point memory, wiping out: Madelung's rules, the
/// behaviour of a Preisach model). With this memory each branch is eq. (3)'s
/// branch from its reversal (u_b, h_b), integrated from there as the model
/// does without memory, plus a straight tilt c·(u − u_b) chosen at the
/// reversal so that the branch ends at (u_a, h_a); an input that reaches u_a
/// forgets both reversals and continues the branch that turned at u_a. The
/// branch shapes are then eq. (3)'s, their ends a Preisach model's; the
/// loop the stage rests on (0 to `rest_cycle_voltage`) is eq. (3)'s own.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReturnPointMemory {
    /// The remembered reversals, oldest first; the last is where the current
    /// branch began. Fixed capacity: remembering allocates nothing.
    points: ArrayVec<Reversal, MEMORY_CAPACITY>,
    /// Sign of the input's last motion (0 before any).
    direction: f64,
    /// The turn at the top of the rest cycle, remembered at rest (the stage
    /// rests at the 0 V end of the 0 → `cycle` → 0 loop); `None` for a virgin
    /// rest.
    rest_top: Option<Reversal>,
}

impl ReturnPointMemory {
    /// The memory at rest: the rest cycle's top, reached from below.
    fn at_rest(rest_top: Option<Reversal>) -> Self {
        let mut memory = Self {
            rest_top,
            ..Self::default()
        };
        if let Some(top) = rest_top {
            memory.points.push(top);
            memory.direction = -top.u.signum();
        }
        memory
    }

    /// The remembered reversals, oldest first.
    pub fn reversals(&self) -> &[Reversal] {
        &self.points
    }

    /// The first remembered value that no run holds, a non-finite one (a
    /// state that comes from outside; one with more reversals than the
    /// capacity does not deserialize).
    fn unreachable(&self) -> Option<(&'static str, f64)> {
        // A direction is a sign, and 0 only before any motion (no reversal
        // but the rest cycle's top, whose memory starts moving down).
        let sign = [-1.0, 0.0, 1.0].contains(&self.direction);
        if !sign || (self.direction == 0.0 && !self.points.is_empty()) {
            return Some(("return-point memory's direction", self.direction));
        }
        self.reversals()
            .iter()
            .flat_map(|r| {
                [
                    ("return-point memory's reversal input", r.u),
                    ("return-point memory's reversal state", r.h),
                    ("return-point memory's reversal tilt", r.tilt),
                ]
            })
            .find(|(_, value)| !value.is_finite())
    }
}

/// The rate-independent asymmetric Bouc-Wen model (seed 001 eq. (3)-(4)); see the
/// module documentation for the reading of the asymmetry term.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AsymmetricBoucWen {
    params: BoucWenParams,
    /// Hysteretic state h [µm].
    h: f64,
    /// Last input u [V].
    u: f64,
    /// The state [`AsymmetricBoucWen::reset`] returns to and the output's zero.
    rest: RestState,
    /// The return-point memory, for a model whose minor loops close
    /// ([`AsymmetricBoucWen::with_return_point_memory`]); boxed, so that a
    /// model without one stays small. Cloned only with the model, never
    /// while it steps.
    memory: Option<Box<ReturnPointMemory>>,
}

impl AsymmetricBoucWen {
    /// A model at its virgin rest: h = 0, u = 0.
    pub fn new(params: BoucWenParams) -> Self {
        Self {
            params,
            h: 0.0,
            u: 0.0,
            rest: RestState::default(),
            memory: None,
        }
    }

    /// A model at the rest of an exercised actuator: at u = 0 on the loop
    /// that cycles between 0 and `cycle_input`, with the output zeroed there.
    ///
    /// From its virgin state h = 0, a Bouc-Wen model does not come back to
    /// where it started: after 0 → 100 → 0 V a stack of this project rests
    /// about 4 % of its stroke extended, and a unipolar drive from that rest
    /// cannot return to the zero it was read from. A real stack has been
    /// poled and operated before any measurement: its rest is the 0 V end of
    /// its working loop, and the sensors are zeroed there. The cycles are
    /// repeated until the state at u = 0 settles (the loop is an attractor);
    /// `cycle_input` = 0 gives the virgin model.
    pub fn at_exercised_rest(params: BoucWenParams, cycle_input: f64) -> Self {
        let mut model = Self::new(params);
        if cycle_input == 0.0 || !cycle_input.is_finite() {
            return model;
        }
        let du = cycle_input.abs() / REST_CYCLE_STEPS;
        for _ in 0..REST_CYCLES {
            let before = model.h;
            model.advance_to(cycle_input, du);
            model.advance_to(0.0, du);
            let settled = (model.h - before).abs() <= 1e-13 * model.h.abs().max(1.0);
            if settled || !model.h.is_finite() {
                break;
            }
        }
        model.rest = RestState {
            h: model.h,
            offset: params.q * model.h,
        };
        model
    }

    /// This model, at its rest, with a [`ReturnPointMemory`]: its minor loops
    /// close. `cycle_input` is the rest cycle
    /// [`AsymmetricBoucWen::at_exercised_rest`] settled it on (0: a virgin
    /// model): the memory holds that cycle's top, so that the rest loop is
    /// one of its closed loops and an excursion past the top continues the
    /// branch that climbed to it.
    pub fn with_return_point_memory(mut self, cycle_input: f64) -> Self {
        self.reset();
        let rest_top = (cycle_input != 0.0 && cycle_input.is_finite()).then(|| Reversal {
            u: cycle_input,
            h: integrate(
                &self.params,
                0.0,
                self.rest.h,
                cycle_input,
                cycle_input.abs() / REST_CYCLE_STEPS,
            ),
            tilt: 0.0,
        });
        self.memory = Some(Box::new(ReturnPointMemory::at_rest(rest_top)));
        self
    }

    /// The return-point memory, for a model that has one.
    pub fn return_point_memory(&self) -> Option<&ReturnPointMemory> {
        self.memory.as_deref()
    }

    /// The first value of the return-point memory that no run holds (its
    /// name and value), for a model that comes from outside.
    pub fn unreachable_memory(&self) -> Option<(&'static str, f64)> {
        self.memory
            .as_deref()
            .and_then(ReturnPointMemory::unreachable)
    }

    pub fn params(&self) -> &BoucWenParams {
        &self.params
    }

    /// The rest state and its output offset.
    pub fn rest(&self) -> RestState {
        self.rest
    }

    /// y = p·u + q·h − y_rest, seed 001 eq. (4) read from the rest [µm].
    pub fn output(&self) -> f64 {
        self.params.p * self.u + self.params.q * self.h - self.rest.offset
    }

    /// The hysteretic state h [µm].
    pub fn hysteretic_state(&self) -> f64 {
        self.h
    }

    /// The last input u [V].
    pub fn input(&self) -> f64 {
        self.u
    }

    /// dy/du at the current point for an input moving in the direction of
    /// `direction` (its sign): p + q·dh/du, with dh/du from eq. (3) in the
    /// module's reading, on the current branch (its tilt included, for a
    /// model with a return-point memory; a turn against the branch's
    /// direction would start another). Used by the inverse model's Newton
    /// steps.
    pub fn output_slope(&self, direction: f64) -> f64 {
        let p = &self.params;
        p.p + p.q * self.branch_slope(direction)
    }

    /// dh/du on the current branch for an input moving in the direction of
    /// `direction`: eq. (3)'s slope at the branch's untilted state, plus its
    /// tilt ([`ReturnPointMemory`]).
    fn branch_slope(&self, direction: f64) -> f64 {
        let (origin, tilt) = self.branch();
        let untilted = self.h - tilt * (self.u - origin);
        self.params.state_slope(self.u, untilted, direction) + tilt
    }

    /// The current branch's origin u_b [V] and tilt [µm/V]: the last
    /// remembered reversal's, (0, 0) for a model without memory or without a
    /// reversal (an untilted branch).
    fn branch(&self) -> (f64, f64) {
        self.memory
            .as_deref()
            .and_then(|memory| memory.reversals().last())
            .map_or((0.0, 0.0), |r| (r.u, r.tilt))
    }

    /// Eq. (3)'s own state on the current branch, h − c·(u − u_b) with the
    /// branch's tilt c and origin u_b (h itself without a memory or a
    /// tilt) [µm]: where it crosses 0, eq. (3)'s slope changes form.
    pub fn branch_state(&self) -> f64 {
        let (origin, tilt) = self.branch();
        self.h - tilt * (self.u - origin)
    }

    /// Sets the input and the hysteretic state (a continuous-state
    /// integrator owns them).
    pub fn set_point(&mut self, u: f64, h: f64) {
        self.u = u;
        self.h = h;
    }

    /// dh/dt while the input moves at `u_rate` = du/dt: eq. (3) in this
    /// module's reading, (dh/du)·u̇, with sgn(du) = sgn(u̇), on the current
    /// branch (with a return-point memory, eq. (3) of the untilted state
    /// plus the branch's tilt, as [`AsymmetricBoucWen::advance_to`]
    /// integrates it). Continuous in u̇ (every term is proportional to it),
    /// so a held input holds h.
    pub fn state_rate(&self, u_rate: f64) -> f64 {
        self.branch_slope(u_rate) * u_rate
    }

    /// For an integrator in time that owns the point (u, h) (a model-exchange
    /// importer's solver): the two functions of the point that rise through
    /// 0 (from ≤ 0 to > 0, an event in FMI 2.0's reading) where the
    /// return-point memory must be updated by
    /// [`AsymmetricBoucWen::settle_memory`], after which both are ≤ 0 again.
    /// `u_rate` is the input's rate, or any quantity of its sign. A jump of
    /// the input is the importer's event (FMI 2.0 has it enter Event Mode
    /// for a discontinuous input); one it integrates across unseen, with the
    /// functions read only after the jump, is a turn the memory misses.
    ///
    /// - `[0]`, a turn: −d·u̇ for the direction d of the last motion, so
    ///   that a held input (0) and a motion that goes on (< 0) lie on one
    ///   side and a turn (> 0) on the other. A model that has not moved since
    ///   its rest has no direction: u̇ there, which marks a start upward; a
    ///   start downward is told by the turn that ends it.
    /// - `[1]`, a wipe-out: d·(u − u_a) for the reversal u_a that the current
    ///   branch closes onto; −1 when it closes onto none.
    ///
    /// Both are −1 (no event ever) for a model without a memory: its rate is
    /// the same function of the point whatever the input did before.
    pub fn memory_event_functions(&self, u_rate: f64) -> [f64; 2] {
        let Some(memory) = self.memory.as_deref() else {
            return [-1.0, -1.0];
        };
        let turn = if memory.direction == 0.0 {
            u_rate
        } else {
            -memory.direction * u_rate
        };
        let wipe_out = match memory.points[..] {
            [.., closes_at, _] => memory.direction * (self.u - closes_at.u),
            _ => -1.0,
        };
        [turn, wipe_out]
    }

    /// The event update of the return-point memory for an integrator in time
    /// (see [`AsymmetricBoucWen::memory_event_functions`]), at the current
    /// point (u, h) with the input moving at `u_rate` (or any quantity of its
    /// sign): an input that has reached, or passed, the reversal its branch
    /// closes onto forgets both and continues the branch that turned there;
    /// an input that turns is remembered turning here, as
    /// [`AsymmetricBoucWen::advance_to`] remembers it. A model that had not
    /// moved since its rest came there from u = 0. `max_du` as for
    /// `advance_to`. Returns whether h changed (only a wipe-out moves it,
    /// onto the branch it continues). Allocates nothing; nothing happens to
    /// a model without memory.
    pub fn settle_memory(&mut self, u_rate: f64, max_du: f64) -> bool {
        let params = self.params;
        let Some(memory) = self.memory.as_deref_mut() else {
            return false;
        };
        if !(self.u.is_finite() && self.h.is_finite() && u_rate.is_finite()) {
            return false;
        }
        let h_before = self.h;
        if memory.direction == 0.0 {
            // Rest is u = 0: a model away from it has moved, the way it went.
            memory.direction = sign_or_zero(self.u);
        }
        let (u, direction) = (self.u, memory.direction);
        let mut wiped = false;
        while let [.., closes_at, _] = memory.points[..] {
            if direction * (u - closes_at.u) < 0.0 {
                break;
            }
            self.u = closes_at.u;
            self.h = closes_at.h;
            memory.points.truncate(memory.points.len() - 2);
            wiped = true;
        }
        if wiped {
            let (origin, tilt) = memory
                .reversals()
                .last()
                .map_or((self.u, 0.0), |r| (r.u, r.tilt));
            let untilted = self.h - tilt * (self.u - origin);
            let untilted = integrate(&params, self.u, untilted, u, max_du);
            self.h = untilted + tilt * (u - origin);
            self.u = u;
        }
        let moving = sign_or_zero(u_rate);
        if moving != 0.0 && moving != memory.direction {
            if memory.direction != 0.0 {
                memory.remember_reversal(&params, self.u, self.h, moving, max_du);
            }
            memory.direction = moving;
        }
        self.h != h_before
    }

    /// Takes `from`'s point (input and hysteretic state), keeping this
    /// model's parameters and rest ([`crate::restore`]).
    /// The return-point memory comes along where both models have one (it is
    /// dynamic state; whether there is one is a parameter).
    pub(crate) fn carry_point(&mut self, from: &Self) {
        self.u = from.u;
        self.h = from.h;
        if let (Some(own), Some(theirs)) = (self.memory.as_deref_mut(), from.memory.as_deref()) {
            let rest_top = own.rest_top;
            *own = theirs.clone();
            own.rest_top = rest_top;
        }
    }

    /// Back to rest: h = h_rest (0 for a virgin model), u = 0, the
    /// return-point memory (if any) holding the rest cycle's top alone.
    pub fn reset(&mut self) {
        self.h = self.rest.h;
        self.u = 0.0;
        if let Some(memory) = self.memory.as_deref_mut() {
            *memory = ReturnPointMemory::at_rest(memory.rest_top);
        }
    }

    /// Integrates h along the straight input path from the last input to `u_new`
    /// with classical RK4 in u, in equal substeps of at most `max_du` volts.
    ///
    /// A non-positive or non-finite `max_du` means a single substep. A non-finite
    /// `u_new` makes the state non-finite (nothing is rejected here; the caller
    /// checks finiteness where it matters). At most [`MAX_SUBSTEPS`] substeps
    /// are taken: a longer path gets longer substeps, so that no input, however
    /// absurd, makes one call run for minutes.
    pub fn advance_to(&mut self, u_new: f64, max_du: f64) {
        if self.memory.is_some() {
            self.advance_with_memory(u_new, max_du);
            return;
        }
        self.h = integrate(&self.params, self.u, self.h, u_new, max_du);
        self.u = u_new;
    }

    /// [`AsymmetricBoucWen::advance_to`] for a model with a return-point
    /// memory ([`ReturnPointMemory`] says what it does): a reversal of the
    /// input is remembered with the tilt that makes its branch end at the
    /// reversal before it; an input that reaches that one forgets both and
    /// goes on along the branch that turned there.
    fn advance_with_memory(&mut self, u_new: f64, max_du: f64) {
        let Some(path) = self.memory_path(u_new, max_du) else {
            return;
        };
        let Some(memory) = self.memory.as_deref_mut() else {
            return;
        };
        if let Some(turn) = path.turn {
            if memory.points.is_full() {
                memory.points.drain(..2);
            }
            memory.points.push(turn);
        }
        memory.points.truncate(path.kept);
        memory.direction = path.direction;
        self.h = path.h;
        self.u = u_new;
    }

    /// Where [`AsymmetricBoucWen::advance_to`] takes a model with a
    /// return-point memory, without moving it: what an inverse model's trial
    /// inputs need, with no copy of the memory. `None` where nothing moves
    /// (u_new is the input) or the model has no memory.
    fn memory_path(&self, u_new: f64, max_du: f64) -> Option<MemoryPath> {
        let params = &self.params;
        let memory = self.memory.as_deref()?;
        let du_total = u_new - self.u;
        if du_total == 0.0 {
            return None;
        }
        if !du_total.is_finite() {
            // No direction to remember; the state turns non-finite as
            // without memory.
            let h = integrate(params, self.u, self.h, u_new, max_du);
            return Some(MemoryPath {
                turn: None,
                kept: memory.points.len(),
                direction: memory.direction,
                h,
                tilt: 0.0,
                untilted: h,
            });
        }
        let direction = du_total.signum();
        let turn = (memory.direction != 0.0 && direction != memory.direction)
            .then(|| memory.turn_at(params, self.u, self.h, direction, max_du));
        // The memory after the turn is remembered: a full one forgets its
        // two oldest reversals first.
        let base = match turn {
            Some(_) if memory.points.is_full() => &memory.points[2..],
            _ => &memory.points[..],
        };
        let point = |i: usize| match turn {
            Some(t) if i == base.len() => t,
            _ => base[i],
        };
        let mut kept = base.len() + usize::from(turn.is_some());
        let (mut u, mut h) = (self.u, self.h);
        // Wiping out: past the reversal this branch closes onto, the branch
        // that turned there goes on.
        while kept >= 2 {
            let closes_at = point(kept - 2);
            if direction * (u_new - closes_at.u) < 0.0 {
                break;
            }
            (u, h) = (closes_at.u, closes_at.h);
            kept -= 2;
        }
        let (origin, tilt) = if kept > 0 {
            let last = point(kept - 1);
            (last.u, last.tilt)
        } else {
            (u, 0.0)
        };
        // eq. (3) integrates the untilted branch; the tilt is added to its state.
        let untilted = integrate(params, u, h - tilt * (u - origin), u_new, max_du);
        Some(MemoryPath {
            turn,
            kept,
            direction,
            h: untilted + tilt * (u_new - origin),
            tilt,
            untilted,
        })
    }

    /// The output and dy/du that [`AsymmetricBoucWen::advance_to`]`(u_new)`
    /// would leave, the model unmoved: the inverse model's trial of an input.
    /// dy/du is the slope on the branch the input ends on, for its direction
    /// of motion. Allocates nothing, with or without a memory.
    pub fn trial(&self, u_new: f64, max_du: f64) -> (f64, f64) {
        let p = &self.params;
        let direction = u_new - self.u;
        let (h, untilted, tilt) = match self.memory_path(u_new, max_du) {
            Some(path) => (path.h, path.untilted, path.tilt),
            None if self.memory.is_some() => {
                return (self.output(), self.output_slope(direction));
            }
            None => {
                let h = integrate(p, self.u, self.h, u_new, max_du);
                (h, h, 0.0)
            }
        };
        let output = p.p * u_new + p.q * h - self.rest.offset;
        let slope = p.p + p.q * (p.state_slope(u_new, untilted, direction) + tilt);
        (output, slope)
    }
}

/// What [`AsymmetricBoucWen::memory_path`] finds.
#[derive(Clone, Copy, Debug)]
struct MemoryPath {
    /// The turn to remember, where the input turns.
    turn: Option<Reversal>,
    /// How many reversals stay (counted after the turn is remembered).
    kept: usize,
    direction: f64,
    /// The hysteretic state at u_new.
    h: f64,
    /// The branch u_new is on: its tilt, and its untilted state there.
    tilt: f64,
    untilted: f64,
}

impl ReturnPointMemory {
    /// Remembers that the input turned at (u, h) to move in `direction`
    /// ([`ReturnPointMemory::turn_at`]).
    fn remember_reversal(
        &mut self,
        params: &BoucWenParams,
        u: f64,
        h: f64,
        direction: f64,
        max_du: f64,
    ) {
        let turn = self.turn_at(params, u, h, direction, max_du);
        if self.points.is_full() {
            self.points.drain(..2);
        }
        self.points.push(turn);
    }

    /// The reversal of an input that turns at (u, h) to move in `direction`,
    /// with the tilt that brings eq. (3)'s branch from there to the last
    /// reversal (the branch of a first reversal, or of one whose predecessor
    /// is not ahead, has none).
    fn turn_at(
        &self,
        params: &BoucWenParams,
        u: f64,
        h: f64,
        direction: f64,
        max_du: f64,
    ) -> Reversal {
        let tilt = match self.reversals().last() {
            Some(closes_at) if direction * (closes_at.u - u) > 0.0 => {
                let untilted_end = integrate(params, u, h, closes_at.u, max_du);
                (closes_at.h - untilted_end) / (closes_at.u - u)
            }
            _ => 0.0,
        };
        Reversal { u, h, tilt }
    }
}

/// The sign of `x`, 0 for ±0 (`f64::signum` gives ±1 there).
fn sign_or_zero(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// h at `u1` along eq. (3)'s branch from (u0, h0), integrated along the
/// straight input path with classical RK4 in u, in equal substeps of at most
/// `max_du` volts (the rules of [`AsymmetricBoucWen::advance_to`]).
#[inline(always)]
fn integrate(params: &BoucWenParams, u0: f64, h0: f64, u1: f64, max_du: f64) -> f64 {
    let du_total = u1 - u0;
    if du_total == 0.0 {
        return h0;
    }
    let ratio = du_total.abs() / max_du;
    // `ratio` is NaN or infinite only for a degenerate max_du or input; one
    // substep then (and never an unbounded loop).
    // A path no longer than max_du (the usual case inside a stage step) is
    // one substep without the ceil, which is a libm call on baseline x86-64.
    let substeps = if ratio <= 1.0 {
        1
    } else if ratio.is_finite() {
        ratio.ceil().clamp(1.0, MAX_SUBSTEPS as f64) as usize
    } else {
        1
    };
    let p = *params;
    // sgn(du) is constant along the straight path (seed 001 eq. (3), |u̇| = u̇·sgn(u̇)).
    let beta_dir = p.beta * du_total.signum();
    // Fast paths: |h|^(n−1)·h and |h|^n without powf for the common n = 1 and n = 2.
    if p.n == 1.0 {
        rk4_path(u0, h0, du_total, substeps, |u, h| {
            p.a - beta_dir * h - p.gamma * h.abs() + p.delta * u
        })
    } else if p.n == 2.0 {
        rk4_path(u0, h0, du_total, substeps, |u, h| {
            let abs_h = h.abs();
            p.a - beta_dir * abs_h * h - p.gamma * abs_h * abs_h + p.delta * u
        })
    } else {
        let n_minus_1 = p.n - 1.0;
        rk4_path(u0, h0, du_total, substeps, |u, h| {
            let abs_h = h.abs();
            let pow = abs_h.powf(n_minus_1); // |h|^(n−1)
            p.a - beta_dir * pow * h - p.gamma * pow * abs_h + p.delta * u
        })
    }
}

/// Classical RK4 for dh/du = f(u, h) from (u0, h0) over `du_total` in `substeps`
/// equal substeps. Substep starts are computed from u0 (no accumulated drift).
/// Any scalar ODE fits: `piezo-identify` integrates seed 001's printed,
/// time-domain reading of eq. (3) with it (u standing for time).
#[inline(always)]
pub fn rk4_path(
    u0: f64,
    h0: f64,
    du_total: f64,
    substeps: usize,
    f: impl Fn(f64, f64) -> f64,
) -> f64 {
    // One substep is what a stage step asks for almost always: the same
    // arithmetic with the count a constant, so the compiler drops the loop and
    // the integer conversions.
    if substeps == 1 {
        rk4_substeps(u0, h0, du_total, 1, &f)
    } else {
        rk4_substeps(u0, h0, du_total, substeps, &f)
    }
}

/// The body of [`rk4_path`].
#[inline(always)]
fn rk4_substeps(
    u0: f64,
    h0: f64,
    du_total: f64,
    substeps: usize,
    f: impl Fn(f64, f64) -> f64,
) -> f64 {
    let du = du_total / substeps as f64;
    let half = 0.5 * du;
    let mut h = h0;
    for i in 0..substeps {
        let u = u0 + du * i as f64;
        let k1 = f(u, h);
        let k2 = f(u + half, h + half * k1);
        let k3 = f(u + half, h + half * k2);
        let k4 = f(u + du, h + du * k3);
        h += du / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    h
}

/// Forward model over a sampled input sequence, starting at rest (h = 0, u = 0):
/// the model is advanced along straight segments 0 → inputs[0] → inputs[1] → …
/// (substeps of at most [`SIMULATE_MAX_DU`]) and the output y (eq. 4) after
/// each sample is returned, one per input.
pub fn simulate(params: BoucWenParams, inputs: &[f64]) -> Vec<f64> {
    let mut model = AsymmetricBoucWen::new(params);
    inputs
        .iter()
        .map(|&u| {
            model.advance_to(u, SIMULATE_MAX_DU);
            model.output()
        })
        .collect()
}

/// The hysteretic state h after each input of `inputs`, written to `states`
/// (one per input), from rest, with input substeps of at most `max_du`: the
/// allocation-free core of [`simulate`] for callers that evaluate many
/// parameter sets on one record. With `return_point_memory` the model closes
/// its minor loops ([`ReturnPointMemory`], from a virgin rest), as
/// FlexureStage's `return_point_memory` runs its stacks.
pub fn hysteretic_states_into(
    params: BoucWenParams,
    inputs: &[f64],
    max_du: f64,
    return_point_memory: bool,
    states: &mut [f64],
) {
    assert_eq!(inputs.len(), states.len(), "one state per input");
    let mut model = AsymmetricBoucWen::new(params);
    if return_point_memory {
        model = model.with_return_point_memory(0.0);
    }
    for (&u, h) in inputs.iter().zip(states.iter_mut()) {
        model.advance_to(u, max_du);
        *h = model.hysteretic_state();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two input paths of 1e7 V in 0.01 V substeps would take 2e9 RK4 steps
    /// (8e9 evaluations of |h|^(n-1), minutes); the cap bounds them to 2e5.
    /// The bound asserted, 2 s, is some 100 times what the capped calls take,
    /// so a slow machine passes and an uncapped loop does not.
    #[test]
    fn an_absurd_input_path_takes_bounded_time() {
        let mut model = AsymmetricBoucWen::new(params(1.7, 0.001));
        let started = std::time::Instant::now();
        model.advance_to(1e7, SIMULATE_MAX_DU);
        model.advance_to(-1e7, SIMULATE_MAX_DU);
        assert!(
            started.elapsed() < std::time::Duration::from_secs(2),
            "{:?}",
            started.elapsed()
        );
    }

    fn params(n: f64, delta: f64) -> BoucWenParams {
        BoucWenParams {
            p: 0.15,
            q: -1.0,
            a: 0.05,
            beta: 0.04,
            gamma: 0.01,
            n,
            delta,
        }
    }

    /// n = 1 on the first ascending branch from rest keeps h ≥ 0, so
    /// dh/du = A − (β+γ)·h + δ·u, a linear ODE with the closed form
    /// h(u) = (A/k − δ/k²)(1 − e^{−k u}) + δ·u/k, k = β + γ.
    #[test]
    fn first_branch_matches_closed_form_for_n_1() {
        for delta in [0.0, 2e-4, -2e-4] {
            let bw = params(1.0, delta);
            let k = bw.beta + bw.gamma;
            let mut model = AsymmetricBoucWen::new(bw);
            for i in 1..=100 {
                let u = i as f64;
                model.advance_to(u, 0.05);
                let exact = (bw.a / k - delta / (k * k)) * (1.0 - (-k * u).exp()) + delta * u / k;
                // RK4 with du = 0.05 V and k·du = 2.5e-3: global error ~ (k·du)^4 ~ 1e-11 of h.
                assert!(
                    (model.hysteretic_state() - exact).abs() < 1e-10,
                    "u = {u}: h = {} vs {exact}",
                    model.hysteretic_state()
                );
            }
        }
    }

    /// n = 2, δ = 0, ascending from rest with h ≥ 0: dh/du = A − k·h², k = β + γ,
    /// so h(u) = sqrt(A/k)·tanh(sqrt(A·k)·u).
    #[test]
    fn first_branch_matches_closed_form_for_n_2() {
        let bw = BoucWenParams {
            beta: 0.8,
            gamma: 0.2,
            ..params(2.0, 0.0)
        };
        let k = bw.beta + bw.gamma;
        let mut model = AsymmetricBoucWen::new(bw);
        for i in 1..=100 {
            let u = i as f64;
            model.advance_to(u, 0.05);
            let exact = (bw.a / k).sqrt() * ((bw.a * k).sqrt() * u).tanh();
            assert!((model.hysteretic_state() - exact).abs() < 1e-10);
        }
    }

    /// The general-n (powf) path agrees with the fast paths at n = 1 and n = 2 when
    /// the exponent is perturbed by a hair, and is continuous in n.
    #[test]
    fn general_exponent_path_is_continuous_with_fast_paths() {
        for n in [1.0, 2.0] {
            let path = [0.0, 80.0, 20.0, 100.0, 0.0];
            let fast = simulate(params(n, 1e-4), &path);
            let general = simulate(params(n + 1e-12, 1e-4), &path);
            for (f, g) in fast.iter().zip(&general) {
                // |h| stays below 1.5 µm, so the 1e-12 change in n moves h by ~1e-12 µm.
                assert!((f - g).abs() < 1e-9, "n = {n}: {f} vs {g}");
            }
        }
    }

    /// Rate independence in the input: the same 0 → 100 → 0 V path, sampled every
    /// 0.01 V or every 2 V, gives the same outputs at the shared samples (the model
    /// does not know the sampling; only the RK4 substeps differ, ≤ 0.05 V each).
    #[test]
    fn loop_does_not_depend_on_input_sampling() {
        let fine: Vec<f64> = (0..=20_000)
            .map(|i| {
                let k = i as f64 * 0.01;
                if k <= 100.0 { k } else { 200.0 - k }
            })
            .collect();
        let coarse: Vec<f64> = fine.iter().step_by(200).copied().collect();
        let run = |inputs: &[f64]| {
            let mut model = AsymmetricBoucWen::new(params(1.5, 1e-4));
            inputs
                .iter()
                .map(|&u| {
                    model.advance_to(u, 0.05);
                    model.output()
                })
                .collect::<Vec<_>>()
        };
        let y_fine = run(&fine);
        let y_coarse = run(&coarse);
        for (j, yc) in y_coarse.iter().enumerate() {
            let yf = y_fine[j * 200];
            // RK4 global error with du ≤ 0.05 V on a memory length of ~20 V: < 1e-9 µm.
            assert!((yf - yc).abs() < 1e-9, "sample {j}: {yf} vs {yc}");
        }
    }

    #[test]
    fn held_input_does_not_move_the_state() {
        let mut model = AsymmetricBoucWen::new(params(1.0, 1e-4));
        model.advance_to(42.0, 0.05);
        let before = model.clone();
        model.advance_to(42.0, 0.05);
        assert_eq!(model, before);
    }

    #[test]
    fn reset_returns_to_rest() {
        let mut model = AsymmetricBoucWen::new(params(1.0, 1e-4));
        model.advance_to(42.0, 0.05);
        model.reset();
        assert_eq!(model, AsymmetricBoucWen::new(params(1.0, 1e-4)));
        assert_eq!(model.output(), 0.0);
    }

    /// Counter-clockwise loop for q < 0: on the way down the output is above the
    /// way up (the piezo lags its voltage).
    #[test]
    fn negative_q_gives_the_piezo_loop_orientation() {
        let up: Vec<f64> = (0..=100).map(f64::from).collect();
        let mut model = AsymmetricBoucWen::new(params(1.0, 0.0));
        let mut y_up = Vec::new();
        for &u in &up {
            model.advance_to(u, 0.05);
            y_up.push(model.output());
        }
        for &u in up.iter().rev().skip(1) {
            model.advance_to(u, 0.05);
            if u > 0.0 && u < 100.0 {
                assert!(model.output() > y_up[u as usize], "u = {u}");
            }
        }
    }

    #[test]
    fn simulate_starts_at_rest_and_returns_one_output_per_input() {
        let bw = params(1.0, 1e-4);
        let y = simulate(bw, &[0.0, 10.0, 5.0]);
        assert_eq!(y.len(), 3);
        assert_eq!(y[0], 0.0);
        let mut model = AsymmetricBoucWen::new(bw);
        model.advance_to(10.0, SIMULATE_MAX_DU);
        assert_eq!(y[1], model.output());
    }

    /// eq. (3)-(4) cannot tell a set from its state-scaled twin.
    #[test]
    fn state_scaling_leaves_the_output_unchanged() {
        let bw = params(1.7, 2e-4);
        let path = [0.0, 80.0, 20.0, 100.0, 35.0, 60.0, 0.0];
        let y = simulate(bw, &path);
        for s in [0.01, 0.5, 3.0, 250.0] {
            let twin = simulate(bw.with_state_scale(s), &path);
            for (a, b) in y.iter().zip(&twin) {
                assert!(
                    (a - b).abs() < 1e-9 * (1.0 + a.abs()),
                    "s = {s}: {a} vs {b}"
                );
            }
        }
        let round_trip = bw.with_state_scale(4.0).with_state_scale(0.25);
        assert!((round_trip.beta - bw.beta).abs() < 1e-15);
        assert!((round_trip.q - bw.q).abs() < 1e-15);
    }

    #[test]
    fn hysteretic_states_into_follows_the_model() {
        let bw = params(1.5, 1e-4);
        let inputs = [10.0, 50.0, 20.0];
        for memory in [false, true] {
            let mut states = [0.0; 3];
            hysteretic_states_into(bw, &inputs, SIMULATE_MAX_DU, memory, &mut states);
            let mut model = AsymmetricBoucWen::new(bw);
            if memory {
                model = model.with_return_point_memory(0.0);
            }
            for (u, h) in inputs.iter().zip(states) {
                model.advance_to(*u, SIMULATE_MAX_DU);
                assert_eq!(model.hysteretic_state(), h, "memory {memory}");
            }
        }
        // The two differ once a minor loop turns back: 50 -> 20 -> 50 closes
        // at the first 50 V state with the memory only.
        let loop_inputs = [50.0, 20.0, 50.0];
        let ends = [false, true].map(|memory| {
            let mut states = [0.0; 3];
            hysteretic_states_into(bw, &loop_inputs, SIMULATE_MAX_DU, memory, &mut states);
            states
        });
        assert!((ends[1][2] - ends[1][0]).abs() < 1e-9, "{ends:?}");
        assert!((ends[0][2] - ends[0][0]).abs() > 1e-6, "{ends:?}");
    }

    /// PZT1 of the stage preset (presets/flexure_stage.json).
    fn stack() -> BoucWenParams {
        BoucWenParams {
            p: 0.136477,
            q: -0.909846,
            a: 0.0245,
            beta: 0.05,
            gamma: 0.005,
            n: 1.0,
            delta: 0.0004,
        }
    }

    /// Cycles of 0 → 8 V → 0 from the exercised rest (the loop MODEL.md §6
    /// measures): without memory the stack sinks by tenths of a micrometre
    /// cycle after cycle; with it every cycle ends where the first began, to
    /// the RK4 error of the tilt's integration (1e-12 µm here).
    #[test]
    fn minor_loops_close_with_a_return_point_memory() {
        let drifting = AsymmetricBoucWen::at_exercised_rest(stack(), 100.0);
        let closing = drifting.clone().with_return_point_memory(100.0);
        let mut ends = Vec::new();
        for mut model in [drifting, closing] {
            for _ in 0..4 {
                for u in (0..=80).chain((0..80).rev()) {
                    model.advance_to(f64::from(u) * 0.1, 0.05);
                }
            }
            ends.push(model.output());
        }
        assert!(
            ends[0] < -0.05,
            "without memory the loop drifts: {}",
            ends[0]
        );
        assert!(ends[1].abs() < 1e-9, "with memory it closes: {}", ends[1]);
    }

    /// Wiping out: past an inner loop's start the branch goes on as if the
    /// loop had never been made, and the rest cycle itself stays eq. (3)'s.
    #[test]
    fn an_excursion_past_a_reversal_wipes_the_inner_loop_out() {
        let rest = AsymmetricBoucWen::at_exercised_rest(stack(), 100.0);
        let with_memory = rest.clone().with_return_point_memory(100.0);
        let mut direct = with_memory.clone();
        direct.advance_to(80.0, 0.05);
        let mut looped = with_memory.clone();
        for u in [60.0, 20.0, 45.0, 30.0, 60.0, 80.0] {
            looped.advance_to(u, 0.05);
        }
        assert!(
            (looped.output() - direct.output()).abs() < 1e-9,
            "{} vs {}",
            looped.output(),
            direct.output()
        );
        // The rest loop 0 → 100 → 0 → 120 V: memory or not, the same outputs.
        let mut plain = rest;
        let mut memory = with_memory;
        for u in [100.0, 0.0, 50.0, 120.0, -20.0] {
            plain.advance_to(u, 0.05);
            memory.advance_to(u, 0.05);
            assert!(
                (plain.output() - memory.output()).abs() < 1e-9,
                "{u} V: {} vs {}",
                plain.output(),
                memory.output()
            );
        }
    }

    /// Dither (the PI's answer to sensor noise) does not move a held stack
    /// with a memory; without one it ratchets (MODEL.md §6). The memory of
    /// 100,000 random reversals stays far from its capacity, by wiping out.
    #[test]
    fn dither_does_not_ratchet_a_stack_with_a_memory() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Uniform};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
        let dither = Uniform::new(-0.025, 0.025).unwrap();
        let rest = AsymmetricBoucWen::at_exercised_rest(stack(), 100.0);
        let mut plain = rest.clone();
        let mut memory = rest.with_return_point_memory(100.0);
        for model in [&mut plain, &mut memory] {
            model.advance_to(50.0, 0.05);
        }
        let held = (plain.output(), memory.output());
        let mut deepest = 0;
        for _ in 0..100_000 {
            let u = 50.0 + dither.sample(&mut rng);
            plain.advance_to(u, 0.05);
            memory.advance_to(u, 0.05);
            deepest = deepest.max(memory.return_point_memory().unwrap().reversals().len());
        }
        plain.advance_to(50.0, 0.05);
        memory.advance_to(50.0, 0.05);
        // Back at 50 V the state is that of the innermost loops' last branch,
        // whose two directions differ in slope by 2·β·|h|·|q| (n = 1): over the
        // dither's 0.05 V, 0.005·|h| µm, about 1.5 nm at h ≈ 0.3 µm. It does
        // not grow with the number of reversals.
        let h = memory.hysteretic_state().abs();
        let width = 2.0 * stack().beta * h * stack().q.abs() * 0.05;
        assert!(
            (memory.output() - held.1).abs() <= width,
            "{} vs {}",
            memory.output(),
            held.1
        );
        assert!(
            (plain.output() - held.0).abs() > 100.0 * width,
            "{} vs {}",
            plain.output(),
            held.0
        );
        assert!(
            deepest < MEMORY_CAPACITY / 2,
            "{deepest} reversals remembered"
        );
    }

    /// Loops nested deeper than the memory holds: the oldest are forgotten,
    /// the model stays finite and the newest loops still close.
    #[test]
    fn a_full_memory_forgets_its_oldest_reversals() {
        let mut model =
            AsymmetricBoucWen::at_exercised_rest(stack(), 100.0).with_return_point_memory(100.0);
        for k in 0..45 {
            let k = f64::from(k);
            model.advance_to(100.0 - k, 0.05);
            model.advance_to(k, 0.05);
        }
        // 89 reversals, each inside the last loop: the memory is full.
        let memory = model.return_point_memory().unwrap();
        assert!(memory.reversals().len() >= MEMORY_CAPACITY - 2);
        assert!(model.unreachable_memory().is_none());
        let before = model.output();
        model.advance_to(44.5, 0.05);
        model.advance_to(44.0, 0.05);
        assert!((model.output() - before).abs() < 1e-12);
        model.reset();
        assert_eq!(model.return_point_memory().unwrap().reversals().len(), 1);
        assert_eq!(model.output(), 0.0);
    }

    #[test]
    fn input_scaling_sees_the_same_actuator_through_a_gain() {
        let bw = params(1.5, 2e-4);
        let path = [0.0, 80.0, 20.0, 100.0, 35.0, 60.0];
        let y = simulate(bw, &path);
        let commands: Vec<f64> = path.iter().map(|u| u / 10.0).collect();
        let mut model = AsymmetricBoucWen::new(bw.with_input_scale(10.0));
        for (u, y) in commands.iter().zip(&y) {
            model.advance_to(*u, SIMULATE_MAX_DU / 10.0);
            assert!(
                (model.output() - y).abs() < 1e-9,
                "{} vs {y}",
                model.output()
            );
        }
    }

    /// The memory's event interface (Model Exchange) and `advance_to` give
    /// the same loops: h integrated in u by RK4 on `state_rate`, with
    /// `settle_memory` called at each turn and where the wipe-out function
    /// reaches 0, against `advance_to` along the same path, at every vertex.
    /// Both a virgin model (its first motion downward, told only by the turn
    /// that ends it) and an exercised rest, whose path runs past its rest
    /// cycle's top; the path wipes out two loops on the way.
    #[test]
    fn the_memorys_event_interface_traces_the_loops_advance_to_does() {
        let path = [-20.0, 30.0, 10.0, 25.0, 15.0, 40.0, 120.0, -5.0];
        for (cycle, start) in [(0.0, 0.0), (100.0, 0.0)] {
            let mut reference = AsymmetricBoucWen::at_exercised_rest(stack(), cycle)
                .with_return_point_memory(cycle);
            let mut by_events = reference.clone();
            let mut u: f64 = start;
            let mut wipe_outs = 0;
            for &vertex in &path {
                reference.advance_to(vertex, 1e-3);
                let direction = (vertex - u).signum();
                if cycle != 0.0 || vertex != path[0] {
                    // The virgin model's first motion, downward, is not an
                    // event: the turn at its end tells it.
                    by_events.settle_memory(direction, 1e-3);
                    assert!(by_events.memory_event_functions(direction)[0] < 0.0);
                }
                let steps = ((vertex - u).abs() / 1e-3).round() as usize;
                let du = (vertex - u) / steps as f64;
                for k in 0..steps {
                    let u0 = u + du * k as f64;
                    let h0 = by_events.hysteretic_state();
                    let slope = |model: &mut AsymmetricBoucWen, u: f64, h: f64| {
                        model.set_point(u, h);
                        model.state_rate(direction) * direction
                    };
                    let k1 = slope(&mut by_events, u0, h0);
                    let k2 = slope(&mut by_events, u0 + du / 2.0, h0 + du / 2.0 * k1);
                    let k3 = slope(&mut by_events, u0 + du / 2.0, h0 + du / 2.0 * k2);
                    let k4 = slope(&mut by_events, u0 + du, h0 + du * k3);
                    by_events.set_point(u0 + du, h0 + du / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4));
                    // The wipe-out points of this path lie on the grid.
                    if by_events.memory_event_functions(direction)[1] >= 0.0 {
                        by_events.settle_memory(direction, 1e-3);
                        wipe_outs += 1;
                    }
                }
                u = vertex;
                assert!(
                    (by_events.hysteretic_state() - reference.hysteretic_state()).abs() < 1e-9,
                    "rest cycle {cycle} V, at {vertex} V: {} vs {}",
                    by_events.hysteretic_state(),
                    reference.hysteretic_state()
                );
                assert_eq!(
                    by_events.return_point_memory().unwrap().reversals().len(),
                    reference.return_point_memory().unwrap().reversals().len()
                );
            }
            assert!(
                wipe_outs >= 2,
                "rest cycle {cycle} V: {wipe_outs} wipe-outs"
            );
        }
        // Without a memory there is nothing to settle and no event.
        let mut plain = AsymmetricBoucWen::new(stack());
        plain.advance_to(5.0, 1e-3);
        assert_eq!(plain.memory_event_functions(-1.0), [-1.0, -1.0]);
        assert!(!plain.settle_memory(-1.0, 1e-3));
    }
}
