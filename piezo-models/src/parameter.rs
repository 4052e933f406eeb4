//! What a parameter may be, declared once as plain data: the models'
//! validation checks values against these declarations, and the FMU crates
//! read the same declarations into their variable tables (min, max, unit,
//! description), so a range is never written twice.
//!
//! A bound is open or closed as the model needs it (a damping ratio of
//! exactly 0 or 1 breaks the closed-form mode response; 0 < ζ < 1). A
//! consumer that can only state inclusive bounds (FMI's min/max) states the
//! nearest double inside an open end ([`Range::min_value`]), a value the
//! model takes.

use std::fmt;

/// One end of a [`Range`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    /// No bound on this side (the value must still be finite).
    Unbounded,
    /// The value may equal the bound.
    Closed(f64),
    /// The value must be strictly beyond the bound.
    Open(f64),
}

impl Bound {
    /// The bound's value, whether open or closed.
    pub const fn value(self) -> Option<f64> {
        match self {
            Bound::Unbounded => None,
            Bound::Closed(v) | Bound::Open(v) => Some(v),
        }
    }

    pub const fn is_open(self) -> bool {
        matches!(self, Bound::Open(_))
    }
}

/// The finite values a parameter may take: between `min` and `max`, each end
/// open, closed or absent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub min: Bound,
    pub max: Bound,
}

impl Range {
    /// Any finite value.
    pub const FINITE: Range = Range {
        min: Bound::Unbounded,
        max: Bound::Unbounded,
    };
    /// x > 0.
    pub const POSITIVE: Range = Range::above(0.0);
    /// x >= 0.
    pub const NON_NEGATIVE: Range = Range::at_least(0.0);

    /// x > `min`.
    pub const fn above(min: f64) -> Range {
        Range {
            min: Bound::Open(min),
            max: Bound::Unbounded,
        }
    }

    /// x >= `min`.
    pub const fn at_least(min: f64) -> Range {
        Range {
            min: Bound::Closed(min),
            max: Bound::Unbounded,
        }
    }

    /// The smallest allowed value, as an inclusive minimum (FMI's `min`): a
    /// closed bound's value, or the nearest double above an open one's that
    /// every reader parses (`> 0` is declared as 2.2250738585072014e-308,
    /// the smallest normal double, which is allowed; 0 is not). The double
    /// next to 0 is subnormal, and C's `strtod` reports a subnormal as out of
    /// range (ERANGE, on which C++'s `std::stod` throws).
    pub const fn min_value(&self) -> Option<f64> {
        match self.min {
            Bound::Unbounded => None,
            Bound::Closed(v) => Some(v),
            Bound::Open(0.0) => Some(f64::MIN_POSITIVE),
            Bound::Open(v) => Some(v.next_up()),
        }
    }

    /// The largest allowed value, as an inclusive maximum (see
    /// [`Range::min_value`]).
    pub const fn max_value(&self) -> Option<f64> {
        match self.max {
            Bound::Unbounded => None,
            Bound::Closed(v) => Some(v),
            Bound::Open(0.0) => Some(-f64::MIN_POSITIVE),
            Bound::Open(v) => Some(v.next_down()),
        }
    }

    /// Whether `value` is finite and within both ends: between the inclusive
    /// [`Range::min_value`] and [`Range::max_value`] the FMUs declare, so
    /// that a model and its FMU agree (a subnormal is not inside `> 0`).
    pub fn contains(&self, value: f64) -> bool {
        value.is_finite()
            && self.min_value().is_none_or(|min| value >= min)
            && self.max_value().is_none_or(|max| value <= max)
    }

    /// The range as a condition on `name`: `n >= 1 (finite)`,
    /// `0 < damping_ratio < 1 (finite)`, or `finite`.
    pub fn condition(&self, name: &str) -> String {
        let lower = match self.min {
            Bound::Unbounded => None,
            Bound::Closed(min) => Some((min, "<=", ">=")),
            Bound::Open(min) => Some((min, "<", ">")),
        };
        let upper = match self.max {
            Bound::Unbounded => None,
            Bound::Closed(max) => Some((max, "<=")),
            Bound::Open(max) => Some((max, "<")),
        };
        match (lower, upper) {
            (None, None) => "finite".to_owned(),
            (Some((min, _, op)), None) => format!("{name} {op} {min} (finite)"),
            (None, Some((max, op))) => format!("{name} {op} {max} (finite)"),
            (Some((min, below, _)), Some((max, op))) => {
                format!("{min} {below} {name} {op} {max} (finite)")
            }
        }
    }

    /// `Ok` when `value` is in the range, else the error that names
    /// `parameter` (a serde path) and the condition.
    pub fn check(&self, parameter: &str, value: f64) -> Result<(), ParamError> {
        if self.contains(value) {
            Ok(())
        } else {
            let field = parameter.rsplit('.').next().unwrap_or(parameter);
            Err(ParamError {
                parameter: parameter.to_owned(),
                value,
                allowed: self.condition(field),
            })
        }
    }
}

/// A real parameter of a model: its field, unit, range and meaning, as plain
/// data that the model's validation and an FMU's variable table both read.
#[derive(Clone, Copy, Debug)]
pub struct RealParameter<P> {
    /// The serde field name (`a` in `{"a": 0.1}`).
    pub field: &'static str,
    /// The symbol the papers and users write (`A`).
    pub symbol: &'static str,
    /// Unit in the FMI/SI spelling (`um/V`; "" for dimensionless or units no
    /// unit definition can carry, which the description then states).
    pub unit: &'static str,
    pub range: Range,
    /// What it means, with its equation (and any unit the unit field cannot
    /// carry).
    pub description: &'static str,
    pub get: fn(&P) -> f64,
    pub set: fn(&mut P, f64),
}

impl<P> RealParameter<P> {
    /// Checks the value `params` holds; `prefix` is the serde path of
    /// `params` in the error.
    pub fn check(&self, prefix: &str, params: &P) -> Result<(), ParamError> {
        self.range
            .check(&format!("{prefix}.{}", self.field), (self.get)(params))
    }
}

/// A parameter outside its allowed range.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamError {
    /// Serde path of the parameter, e.g. "actuators[1].hysteresis.n".
    pub parameter: String,
    /// The offending value.
    pub value: f64,
    /// What is allowed, e.g. "n >= 1".
    pub allowed: String,
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Display alone writes every digit of 1e-300.
        let magnitude = self.value.abs();
        let value = if self.value == 0.0 || (1e-4..1e7).contains(&magnitude) {
            format!("{}", self.value)
        } else {
            format!("{:e}", self.value)
        };
        write!(
            f,
            "parameter {} = {value} is out of range (allowed: {})",
            self.parameter, self.allowed
        )
    }
}

impl std::error::Error for ParamError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_ends_exclude_their_bound_and_closed_ends_include_it() {
        let damping = Range {
            min: Bound::Open(0.0),
            max: Bound::Open(1.0),
        };
        assert!(!damping.contains(0.0) && !damping.contains(1.0));
        assert!(damping.contains(1e-9) && damping.contains(1.0 - 1e-9));
        let step = Range {
            min: Bound::Closed(1e-4),
            max: Bound::Closed(10.0),
        };
        assert!(step.contains(1e-4) && step.contains(10.0));
        assert!(!step.contains(0.99e-4) && !step.contains(10.0 + 1e-9));
        // FMI's min and max are inclusive: the nearest values inside.
        assert_eq!(
            (damping.min_value(), damping.max_value()),
            (Some(f64::MIN_POSITIVE), Some(1.0 - f64::EPSILON / 2.0))
        );
        assert!(damping.contains(damping.min_value().unwrap()));
        // A subnormal lies below the smallest normal double the FMU declares.
        assert!(!damping.contains(1e-310) && !Range::POSITIVE.contains(5e-324));
        assert!(damping.contains(damping.max_value().unwrap()));
        assert_eq!(step.min_value(), Some(1e-4));
    }

    #[test]
    fn nothing_non_finite_is_in_any_range() {
        for range in [Range::FINITE, Range::POSITIVE, Range::at_least(1.0)] {
            assert!(!range.contains(f64::NAN));
            assert!(!range.contains(f64::INFINITY));
        }
        assert!(!Range::FINITE.contains(f64::NEG_INFINITY));
    }

    #[test]
    fn the_error_names_the_path_and_the_condition() {
        let e = Range::at_least(1.0)
            .check("coupling.y_from_pzt2.n", 0.5)
            .unwrap_err();
        assert_eq!(e.parameter, "coupling.y_from_pzt2.n");
        assert_eq!(e.allowed, "n >= 1 (finite)");
        let tiny = Range::POSITIVE.check("amplifier.gain", 1e-310).unwrap_err();
        assert_eq!(
            tiny.to_string(),
            "parameter amplifier.gain = 1e-310 is out of range (allowed: gain > 0 (finite))"
        );
        assert_eq!(
            Range::FINITE.check("p", f64::NAN).unwrap_err().allowed,
            "finite"
        );
        let zeta = Range {
            min: Bound::Open(0.0),
            max: Bound::Open(1.0),
        };
        assert_eq!(
            zeta.condition("damping_ratio"),
            "0 < damping_ratio < 1 (finite)"
        );
    }
}
