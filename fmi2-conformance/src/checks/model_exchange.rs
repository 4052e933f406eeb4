//! Checks of the Model Exchange interface, for an FMU that offers it (each is
//! a no-op for a co-simulation-only FMU). Written from the standard and the
//! modelDescription: the state vector is what ModelStructure/Derivatives
//! declares, the dependencies are what it lists.

use std::ptr;

use fmi_sys::fmi2 as sys;

use super::{assert_logged, has_message};
use crate::model_exchange::state_references;
use crate::{ERROR, Fmu, Instance, OK};

/// Calls a Model Exchange `function` on `inst` with valid arguments.
pub(super) fn probe(inst: &mut Instance<'_>, function: &str) -> sys::fmi2Status {
    let n = inst.fmu.number_of_states();
    let ni = inst.fmu.number_of_event_indicators();
    match function {
        "fmi2EnterEventMode" => inst.enter_event_mode(),
        "fmi2NewDiscreteStates" => inst.new_discrete_states().0,
        "fmi2EnterContinuousTimeMode" => inst.enter_continuous_time_mode(),
        "fmi2CompletedIntegratorStep" => inst.completed_integrator_step().0,
        "fmi2SetTime" => inst.set_time(inst.time),
        "fmi2SetContinuousStates" => inst.set_continuous_states(&vec![0.0; n]),
        "fmi2GetDerivatives" => inst.get_derivatives(n).0,
        "fmi2GetEventIndicators" => inst.get_event_indicators(ni).0,
        "fmi2GetContinuousStates" => inst.get_continuous_states(n).0,
        "fmi2GetNominalsOfContinuousStates" => inst.get_nominals(n).0,
        other => panic!("no probe for {other}"),
    }
}

/// A model-exchange instance in continuous-time mode, moved away from rest:
/// its first Real input at 4 (and the others at 2), integrated over 200 µs.
fn moving<'a>(fmu: &'a Fmu, name: &str) -> Instance<'a> {
    let mut inst = fmu.instantiate_model_exchange(name, false);
    inst.initialize();
    inst.event_iteration();
    set_inputs(&inst, 4.0);
    inst.integrate_rk4(5e-6, 40);
    inst
}

fn set_inputs(inst: &Instance<'_>, first: f64) {
    let inputs: Vec<u32> = inst
        .fmu
        .variables
        .iter()
        .filter(|v| v.causality == fmi_schema::fmi2::Causality::Input && v.kind == "Real")
        .map(|v| v.vr)
        .collect();
    let values: Vec<f64> = (0..inputs.len())
        .map(|i| if i == 0 { first } else { 2.0 + i as f64 })
        .collect();
    assert_eq!(
        inst.set_real(&inputs, &values),
        OK,
        "{:#?}",
        inst.take_log()
    );
}

/// The state vector, the derivatives and the nominals agree with the
/// variables that modelDescription declares for them: `fmi2GetReal` of the
/// states and of their derivatives reads what the vector calls return, bit
/// for bit; nominals are positive and finite, before initialization too.
pub fn model_exchange_vectors_match_the_variables(fmu: &Fmu) {
    if !fmu.offers_model_exchange() {
        return;
    }
    let n = fmu.number_of_states();
    let references = state_references(fmu);
    assert_eq!(references.len(), n);
    let fresh = fmu.instantiate_model_exchange("nominals", false);
    let (status, nominals) = fresh.get_nominals(n);
    assert_eq!(
        status,
        OK,
        "nominals in Instantiated: {:#?}",
        fresh.take_log()
    );
    assert!(
        nominals.iter().all(|v| v.is_finite() && *v > 0.0),
        "{nominals:?}"
    );

    let inst = moving(fmu, "vectors");
    let (status, x): (_, Vec<f64>) = inst.get_continuous_states(n);
    assert_eq!(status, OK);
    let (status, dx): (_, Vec<f64>) = inst.get_derivatives(n);
    assert_eq!(status, OK);
    let state_vrs: Vec<u32> = references.iter().map(|(s, _)| *s).collect();
    let derivative_vrs: Vec<u32> = references.iter().map(|(_, d)| *d).collect();
    let (status, read_x) = inst.get_real(&state_vrs);
    assert_eq!(status, OK);
    let (status, read_dx) = inst.get_real(&derivative_vrs);
    assert_eq!(status, OK);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(&x),
        bits(&read_x),
        "fmi2GetContinuousStates vs the state variables"
    );
    assert_eq!(
        bits(&dx),
        bits(&read_dx),
        "fmi2GetDerivatives vs the derivative variables"
    );
    assert!(x.iter().any(|v| *v != 0.0), "the states moved: {x:?}");
    let (status, nominals) = inst.get_nominals(n);
    assert_eq!(status, OK);
    assert!(
        nominals.iter().all(|v| v.is_finite() && *v > 0.0),
        "{nominals:?}"
    );
    let ni = fmu.number_of_event_indicators();
    assert_eq!(inst.get_event_indicators(ni).0, OK);
}

/// Wrong lengths, NULL vectors, non-finite states and times, and NULL
/// out-arguments are refused with fmi2Error and a message naming the function;
/// a refused fmi2SetContinuousStates changes no state.
pub fn model_exchange_arguments_are_checked(fmu: &Fmu) {
    if !fmu.offers_model_exchange() {
        return;
    }
    let n = fmu.number_of_states();
    let b = &fmu.binding;
    let refused =
        |function: &str, needle: &str, call: &dyn Fn(&Instance<'_>) -> sys::fmi2Status| {
            let inst = moving(fmu, "arguments");
            let (_, before) = inst.get_continuous_states(n);
            assert_eq!(call(&inst), ERROR, "{function} ({needle}) accepted");
            assert_logged(&inst.take_log(), function, needle);
            let (status, after) = inst.get_continuous_states(n);
            assert_eq!(status, OK, "states readable in the error state");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&before),
                bits(&after),
                "{function} refused but changed the states"
            );
            assert_eq!(
                inst.set_time(0.0),
                ERROR,
                "the instance is in its error state"
            );
        };
    refused("fmi2SetContinuousStates", "nx is", &|i| {
        i.set_continuous_states(&vec![1.0; n - 1])
    });
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    refused("fmi2SetContinuousStates", "x[] is NULL", &|i| unsafe {
        b.fmi2SetContinuousStates(i.c, ptr::null(), n)
    });
    refused("fmi2SetContinuousStates", "only finite", &|i| {
        let (_, mut x) = i.get_continuous_states(n);
        x[n / 2] = f64::NAN;
        x[0] += 1.0;
        i.set_continuous_states(&x)
    });
    refused("fmi2SetContinuousStates", "only finite", &|i| {
        let (_, mut x) = i.get_continuous_states(n);
        x[n - 1] = f64::INFINITY;
        i.set_continuous_states(&x)
    });
    refused("fmi2SetTime", "finite", &|i| i.set_time(f64::NAN));
    refused("fmi2GetDerivatives", "nx is", &|i| {
        i.get_derivatives(n + 1).0
    });
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    refused("fmi2GetDerivatives", "NULL", &|i| unsafe {
        b.fmi2GetDerivatives(i.c, ptr::null_mut(), n)
    });
    refused("fmi2GetContinuousStates", "nx is", &|i| {
        i.get_continuous_states(0).0
    });
    refused("fmi2GetNominalsOfContinuousStates", "nx is", &|i| {
        i.get_nominals(n - 1).0
    });
    refused("fmi2GetEventIndicators", "ni is", &|i| {
        i.get_event_indicators(fmu.number_of_event_indicators() + 1)
            .0
    });
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    refused("fmi2CompletedIntegratorStep", "NULL", &|i| unsafe {
        let mut flag = 0;
        b.fmi2CompletedIntegratorStep(i.c, 1, ptr::null_mut(), &mut flag)
    });
    refused("fmi2NewDiscreteStates", "NULL", &|i| {
        assert_eq!(i.enter_event_mode(), OK);
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe { b.fmi2NewDiscreteStates(i.c, ptr::null_mut()) }
    });
    // With no event indicators, a NULL vector of length 0 is a valid call.
    let inst = moving(fmu, "no-indicators");
    if fmu.number_of_event_indicators() == 0 {
        assert_eq!(
            // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are
            // the ones under test, which the layer must refuse without touching them, and every
            // other pointer is to a local that outlives the call with at least the length
            // passed.
            unsafe { b.fmi2GetEventIndicators(inst.c, ptr::null_mut(), 0) },
            OK
        );
    }
    // A co-simulation call on a model-exchange instance says why it is refused.
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    assert_eq!(unsafe { b.fmi2DoStep(inst.c, 0.0, 1e-4, 1) }, ERROR);
    let log = inst.take_log();
    assert!(
        has_message(&log, "illegal call sequence") && has_message(&log, "Co-Simulation"),
        "{log:#?}"
    );
}

/// A state derivative that overflows is never handed out: from finite states
/// at the edge of the floating-point range (f64::MAX, where any rate that
/// grows with its state overflows), `fmi2GetDerivatives` and `fmi2GetReal` of
/// the derivative variables return fmi2Error and say which derivative, and
/// `fmi2GetReal` of the states still reads them.
pub fn non_finite_derivatives_are_refused(fmu: &Fmu) {
    if !fmu.offers_model_exchange() {
        return;
    }
    let n = fmu.number_of_states();
    let references = state_references(fmu);
    let derivative_vrs: Vec<u32> = references.iter().map(|(_, d)| *d).collect();
    let state_vrs: Vec<u32> = references.iter().map(|(s, _)| *s).collect();
    let at_the_edge = |name: &str| {
        let inst = moving(fmu, name);
        assert_eq!(inst.set_continuous_states(&vec![f64::MAX; n]), OK);
        inst
    };

    let inst = at_the_edge("overflow-vector");
    let (status, dx) = inst.get_derivatives(n);
    assert_eq!(status, ERROR, "fmi2GetDerivatives handed out {dx:?}");
    assert_logged(
        &inst.take_log(),
        "fmi2GetDerivatives",
        "outside the model's domain",
    );
    let (status, x) = inst.get_real(&state_vrs);
    assert_eq!(status, OK, "the states stay readable in the error state");
    assert!(x.iter().all(|v| *v == f64::MAX), "{x:?}");

    let inst = at_the_edge("overflow-variables");
    let (status, dx) = inst.get_real(&derivative_vrs);
    assert_eq!(
        status, ERROR,
        "fmi2GetReal of the derivatives handed out {dx:?}"
    );
    assert_logged(
        &inst.take_log(),
        "fmi2GetReal",
        "outside the model's domain",
    );
    assert_eq!(
        inst.set_time(0.0),
        ERROR,
        "the instance is in its error state"
    );
}

/// The dependencies of ModelStructure/Derivatives and /Outputs hold: from a
/// moving state, a state or input that a derivative (or output) does not list
/// does not change it when it changes, bit for bit.
pub fn derivative_dependencies_hold(fmu: &Fmu) {
    if !fmu.offers_model_exchange() {
        return;
    }
    let n = fmu.number_of_states();
    let structure = &fmu.description.model_structure;
    let references = state_references(fmu);
    // Knowns: the states (by ScalarVariable index) and the Real inputs.
    let state_indices: Vec<u32> = structure
        .derivatives
        .unknowns
        .iter()
        .map(|u| crate::model_exchange::state_of(fmu, u.index))
        .collect();
    let inputs: Vec<(u32, u32)> = fmu
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == fmi_schema::fmi2::Causality::Input && v.kind == "Real")
        .map(|(i, v)| (i as u32 + 1, v.vr))
        .collect();
    let outputs: Vec<(u32, u32, &[u32])> = structure
        .outputs
        .unknowns
        .iter()
        .filter(|u| fmu.variables[u.index as usize - 1].kind == "Real")
        .map(|u| {
            (
                u.index,
                fmu.variables[u.index as usize - 1].vr,
                u.dependencies.as_slice(),
            )
        })
        .collect();
    let output_vrs: Vec<u32> = outputs.iter().map(|(_, vr, _)| *vr).collect();
    let inst = moving(fmu, "dependencies");
    let (_, x0) = inst.get_continuous_states(n);
    let snapshot = |inst: &Instance<'_>| {
        let (status, dx) = inst.get_derivatives(n);
        assert_eq!(status, OK, "{:#?}", inst.take_log());
        let (status, y) = inst.get_real(&output_vrs);
        assert_eq!(status, OK);
        (dx, y)
    };
    let (dx0, y0) = snapshot(&inst);
    let mut failures = Vec::new();
    let mut compare = |known: u32, what: &str, dx: &[f64], y: &[f64]| {
        for (k, unknown) in structure.derivatives.unknowns.iter().enumerate() {
            if !unknown.dependencies.contains(&known) && dx[k].to_bits() != dx0[k].to_bits() {
                failures.push(format!(
                    "derivative {} (index {}) changed with {what} (index {known}), which its \
                     dependencies {:?} do not list",
                    fmu.variables[unknown.index as usize - 1].name,
                    unknown.index,
                    unknown.dependencies
                ));
            }
        }
        for (j, (index, _, dependencies)) in outputs.iter().enumerate() {
            // An output that is itself a state lists no dependencies (as the
            // Reference FMUs declare one): it is the known.
            if *index == known {
                continue;
            }
            if !dependencies.contains(&known) && y[j].to_bits() != y0[j].to_bits() {
                failures.push(format!(
                    "output {} (index {index}) changed with {what} (index {known}), which its \
                     dependencies {dependencies:?} do not list",
                    fmu.variables[*index as usize - 1].name
                ));
            }
        }
    };
    for (j, index) in state_indices.iter().enumerate() {
        let mut x = x0.clone();
        x[j] = x[j] * (1.0 + 1e-3) + 1e-3;
        assert_eq!(inst.set_continuous_states(&x), OK);
        let (dx, y) = snapshot(&inst);
        let name = &fmu.variables[*index as usize - 1].name;
        compare(*index, &format!("state {name}"), &dx, &y);
        assert_eq!(inst.set_continuous_states(&x0), OK);
    }
    for (index, vr) in &inputs {
        let old = inst.get_real_one(*vr);
        assert_eq!(inst.set_real(&[*vr], &[old + 0.5]), OK);
        let (dx, y) = snapshot(&inst);
        let name = &fmu.variables[*index as usize - 1].name;
        compare(*index, &format!("input {name}"), &dx, &y);
        assert_eq!(inst.set_real(&[*vr], &[old]), OK);
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // The declared state-vector order is the vector calls' order.
    assert_eq!(references.len(), n);
}
