//! Rebuilding a model from a state that comes from outside.
//!
//! A model's serialized form holds its parameters, its dynamic state and the
//! values it derives from the parameters at construction (rates, gains, the
//! exercised rests, copies of the parameters inside each component, caches).
//! Bytes written on purpose (an FMU state with a valid checksum but made-up
//! values) can make those disagree: an amplifier whose copy of its limits has
//! `v_min > v_max`, a mode whose cached coefficients belong to another
//! frequency. The models' `rebuilt` methods therefore take only the
//! parameters and the dynamic state from such a value and build everything
//! else again as their constructors do, validating the parameters as they
//! do; their `unreachable_state` methods name a dynamic state variable that
//! no run of the model holds.

use std::fmt;

/// A dynamic state variable holding a value no run of the model reaches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnreachableState {
    /// What the variable is, for the user.
    pub variable: &'static str,
    pub value: f64,
    /// What a run of the model can hold there.
    pub allowed: &'static str,
}

impl UnreachableState {
    /// `Some` for a `value` of `variable` that is not finite.
    pub(crate) fn unless_finite(variable: &'static str, value: f64) -> Option<UnreachableState> {
        (!value.is_finite()).then_some(UnreachableState {
            variable,
            value,
            allowed: "a finite value",
        })
    }
}

impl fmt::Display for UnreachableState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the {} = {} (allowed: {})",
            self.variable, self.value, self.allowed
        )
    }
}

impl std::error::Error for UnreachableState {}
