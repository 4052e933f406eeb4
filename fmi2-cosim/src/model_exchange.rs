//! FMI 2.0 Model Exchange, generic over the model: what a model provides
//! beyond [`CoSimModel`] (continuous states, their derivatives and nominal
//! values, event indicators, discrete-state updates), and the rules of the
//! Model Exchange calls on an instance (FMI 2.0.4 §3.2).
//!
//! The importer's integrator owns the time and the continuous states: it sets
//! them (`fmi2SetTime`, `fmi2SetContinuousStates`), reads the derivatives and
//! advances. The model only evaluates its right-hand side at the point it is
//! given; outputs are computed from the same states, so every getter sees the
//! point the integrator last set.

use crate::instance::Instance;
use crate::model::{CoSimModel, Context, ModelError};
use crate::status::{FmiFunction, FmiState, Status};
use crate::variables::continuous_states;

/// What `fmi2NewDiscreteStates` reports (`fmi2EventInfo`), apart from
/// `newDiscreteStatesNeeded`, which the layer answers with false: one update
/// settles a model of this layer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EventUpdate {
    /// The model asks the importer to end the simulation.
    pub terminate_simulation: bool,
    /// `fmi2GetNominalsOfContinuousStates` would now answer differently.
    pub nominals_changed: bool,
    /// The update changed the continuous states (the integrator must read them
    /// again).
    pub values_changed: bool,
    /// The next time event, if the model has one.
    pub next_event_time: Option<f64>,
}

/// A model that runs as FMI 2.0 Model Exchange as well as Co-Simulation. Its
/// `CoSimModel::MODEL_EXCHANGE` is `Some`, and its variable table marks each
/// state derivative with [`Variable::derivative_of`](crate::Variable::derivative_of);
/// the derivatives' order in the table is the order of the state vector that
/// every method here reads or writes (length
/// `ModelExchangeInfo::number_of_continuous_states`).
///
/// The layer calls these only in legal states, with slices of the right length
/// and finite states; the model never sees a pointer.
pub trait ModelExchange: CoSimModel {
    /// Writes the continuous states.
    fn continuous_states(&self, states: &mut [f64]);

    /// Makes `states` the continuous states (every value finite).
    fn set_continuous_states(&mut self, states: &[f64]);

    /// Writes the time derivatives of the states at `time`, for the current
    /// states and inputs. Must not allocate. The layer refuses to hand out a
    /// non-finite derivative.
    fn derivatives(&self, time: f64, derivatives: &mut [f64]);

    /// Writes a positive, finite nominal magnitude of each state (the scale an
    /// integrator's absolute tolerance is relative to), from the current
    /// parameters. Also called before initialization.
    fn nominals(&self, nominals: &mut [f64]);

    /// Writes the event indicators (`ModelExchangeInfo::number_of_event_indicators`
    /// of them). A model without state events has none.
    fn event_indicators(&self, _time: f64, _indicators: &mut [f64]) {}

    /// Event mode, `fmi2NewDiscreteStates`: updates the discrete states at
    /// `time`. A model without discrete states keeps the default.
    fn update_discrete_states(
        &mut self,
        _ctx: &mut Context<'_>,
        _time: f64,
    ) -> Result<EventUpdate, ModelError> {
        Ok(EventUpdate::default())
    }

    /// `fmi2CompletedIntegratorStep`: the integrator accepted the step that
    /// ended at `time` with the current states. Returns `Status::Warning` when
    /// it logged a warning; an error ends the simulation (a state that left the
    /// model's domain).
    fn completed_integrator_step(
        &mut self,
        _ctx: &mut Context<'_>,
        _time: f64,
    ) -> Result<Status, ModelError> {
        Ok(Status::Ok)
    }
}

/// The number of continuous states of `M` (0 for a co-simulation-only model).
pub(crate) fn number_of_states<M: CoSimModel>() -> usize {
    M::MODEL_EXCHANGE.map_or(0, |me| me.number_of_continuous_states)
}

/// The name of the derivative of state `k`, for messages.
fn derivative_name<M: CoSimModel>(k: usize) -> &'static str {
    continuous_states(M::variables())
        .get(k)
        .map_or("a state derivative", |(_, d)| M::variables()[*d].name)
}

/// The name of state `k`, for messages.
fn state_name<M: CoSimModel>(k: usize) -> &'static str {
    continuous_states(M::variables())
        .get(k)
        .map_or("a state", |(s, _)| M::variables()[*s].name)
}

/// The answer of `fmi2NewDiscreteStates`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct EventInfo {
    pub new_discrete_states_needed: bool,
    pub update: EventUpdate,
}

impl<M: ModelExchange> Instance<M> {
    /// Refuses a vector whose length is not the model's.
    fn check_length(
        &self,
        function: FmiFunction,
        what: &str,
        given: usize,
        expected: usize,
    ) -> Result<(), Status> {
        if given == expected {
            Ok(())
        } else {
            Err(self.error(
                function,
                format_args!("{what} is {given} but this model has {expected}"),
            ))
        }
    }

    pub(crate) fn enter_event_mode(&mut self) -> Status {
        self.state = FmiState::EventMode;
        Status::Ok
    }

    pub(crate) fn enter_continuous_time_mode(&mut self) -> Status {
        self.state = FmiState::ContinuousTimeMode;
        Status::Ok
    }

    pub(crate) fn new_discrete_states(&mut self) -> Result<EventInfo, Status> {
        let function = FmiFunction::NewDiscreteStates;
        let time = self.time;
        let mut ctx = Context {
            env: &self.env,
            function,
        };
        match self.model.update_discrete_states(&mut ctx, time) {
            Ok(update) => Ok(EventInfo {
                new_discrete_states_needed: false,
                update,
            }),
            Err(e) => Err(self.error(function, format_args!("at t = {time}: {e}"))),
        }
    }

    pub(crate) fn completed_integrator_step(&mut self) -> Status {
        let function = FmiFunction::CompletedIntegratorStep;
        let time = self.time;
        let mut ctx = Context {
            env: &self.env,
            function,
        };
        match self.model.completed_integrator_step(&mut ctx, time) {
            Ok(status) => status,
            Err(e) => self.error(function, format_args!("at t = {time}: {e}")),
        }
    }

    pub(crate) fn set_time(&mut self, time: f64) -> Status {
        if !time.is_finite() {
            return self.error(
                FmiFunction::SetTime,
                format_args!("time must be finite (got {time})"),
            );
        }
        self.time = time;
        Status::Ok
    }

    /// Sets every state, or none when one is not finite.
    pub(crate) fn set_continuous_states(&mut self, states: &[f64]) -> Status {
        let function = FmiFunction::SetContinuousStates;
        if let Err(status) =
            self.check_length(function, "nx", states.len(), number_of_states::<M>())
        {
            return status;
        }
        if let Some(k) = states.iter().position(|x| !x.is_finite()) {
            return self.error(
                function,
                format_args!(
                    "x[{k}] ({}) is {}; only finite states are accepted",
                    state_name::<M>(k),
                    states[k]
                ),
            );
        }
        self.forget_preview();
        self.model.set_continuous_states(states);
        Status::Ok
    }

    pub(crate) fn get_continuous_states(&self, states: &mut [f64]) -> Status {
        let function = FmiFunction::GetContinuousStates;
        if let Err(status) =
            self.check_length(function, "nx", states.len(), number_of_states::<M>())
        {
            return status;
        }
        let (model, status) = self.readable(function, || true);
        model.continuous_states(states);
        status
    }

    pub(crate) fn get_derivatives(&self, derivatives: &mut [f64]) -> Status {
        let function = FmiFunction::GetDerivatives;
        if let Err(status) =
            self.check_length(function, "nx", derivatives.len(), number_of_states::<M>())
        {
            return status;
        }
        let (model, status) = self.readable(function, || true);
        model.derivatives(self.time, derivatives);
        drop(model);
        if let Some(k) = derivatives.iter().position(|d| !d.is_finite()) {
            return self.error(
                function,
                format_args!(
                    "at t = {}: {} is {}; the states or inputs are outside the model's domain",
                    self.time,
                    derivative_name::<M>(k),
                    derivatives[k]
                ),
            );
        }
        status
    }

    pub(crate) fn get_event_indicators(&self, indicators: &mut [f64]) -> Status {
        let function = FmiFunction::GetEventIndicators;
        let expected = M::MODEL_EXCHANGE.map_or(0, |me| me.number_of_event_indicators);
        if let Err(status) = self.check_length(function, "ni", indicators.len(), expected) {
            return status;
        }
        let (model, status) = self.readable(function, || true);
        model.event_indicators(self.time, indicators);
        status
    }

    pub(crate) fn get_nominals(&self, nominals: &mut [f64]) -> Status {
        let function = FmiFunction::GetNominalsOfContinuousStates;
        if let Err(status) =
            self.check_length(function, "nx", nominals.len(), number_of_states::<M>())
        {
            return status;
        }
        let (model, status) = self.readable(function, || true);
        model.nominals(nominals);
        drop(model);
        // FMI 2.0.4 §3.2.2: nominals are positive; 1.0 is the standard's
        // default when a model cannot say.
        for nominal in nominals.iter_mut() {
            if !(nominal.is_finite() && *nominal > 0.0) {
                *nominal = 1.0;
            }
        }
        status
    }
}
