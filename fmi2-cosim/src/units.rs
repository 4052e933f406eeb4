//! Unit definitions that many models share: SI units and their decimal
//! multiples, with their base-unit exponents as FMI 2.0 `<BaseUnit>` wants them.
//! A model lists the ones it uses in `CoSimModel::UNITS`, beside its own.

use crate::model::{BaseUnit, DisplayUnit, UnitDefinition};

/// Volt: kg·m²·s⁻³·A⁻¹.
pub const VOLT: UnitDefinition = UnitDefinition {
    name: "V",
    base: BaseUnit {
        kg: 1,
        m: 2,
        s: -3,
        a: -1,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

/// Micrometre.
pub const MICROMETRE: UnitDefinition = UnitDefinition {
    name: "um",
    base: BaseUnit {
        m: 1,
        factor: 1e-6,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

/// Millimetre.
pub const MILLIMETRE: UnitDefinition = UnitDefinition {
    name: "mm",
    base: BaseUnit {
        m: 1,
        factor: 1e-3,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

const DEG_PER_RAD: f64 = 180.0 / std::f64::consts::PI;

/// Radian, shown in degrees by importers that honour display units.
pub const RADIAN: UnitDefinition = UnitDefinition {
    name: "rad",
    base: BaseUnit {
        rad: 1,
        ..BaseUnit::NONE
    },
    display_units: &[DisplayUnit {
        name: "deg",
        factor: DEG_PER_RAD,
        offset: 0.0,
    }],
};

/// Hertz.
pub const HERTZ: UnitDefinition = UnitDefinition {
    name: "Hz",
    base: BaseUnit {
        s: -1,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

/// Second.
pub const SECOND: UnitDefinition = UnitDefinition {
    name: "s",
    base: BaseUnit {
        s: 1,
        ..BaseUnit::NONE
    },
    display_units: &[],
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degree_display_unit_converts_radians() {
        let deg = RADIAN.display_units[0];
        assert!((deg.factor * std::f64::consts::PI - 180.0).abs() < 1e-12);
    }
}
