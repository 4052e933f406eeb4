//! What the fixture computes, through the C ABI: every output equals its input
//! as soon as the input is set (before any step), in initialization mode and
//! between steps, the String one included; the calculated parameter is the
//! start time; the locals integrate and count; `time` is the time; the
//! constant never moves; a reset brings back the start values.

use fmi2_conformance::{Fmu, GetDiscrete, Instance, OK, StringValues, WARNING, workspace};
use fmu_fixture::{Feedthrough, REAL_CONSTANT, STRING_PARAMETER_START};

fn fixture() -> Fmu {
    workspace::load::<Feedthrough>("fmu-fixture")
}

fn vr(fmu: &Fmu, name: &str) -> u32 {
    fmu.variable(name).vr
}

/// Sets one value of each input and reads each output back with no step between.
fn assert_fed_through(
    fmu: &Fmu,
    inst: &Instance<'_>,
    real: f64,
    discrete: f64,
    int: i32,
    flag: bool,
    text: &str,
) {
    let inputs = [
        vr(fmu, "real_continuous_input"),
        vr(fmu, "real_discrete_input"),
    ];
    let outputs = [
        vr(fmu, "real_continuous_output"),
        vr(fmu, "real_discrete_output"),
    ];
    assert_eq!(inst.set_real(&inputs, &[real, discrete]), OK);
    assert_eq!(inst.set_integer(&[vr(fmu, "integer_input")], &[int]), OK);
    assert_eq!(inst.set_boolean(&[vr(fmu, "boolean_input")], &[flag]), OK);
    let (status, reals) = inst.get_real(&outputs);
    assert_eq!(status, OK);
    assert_eq!(reals, [real, discrete]);
    let (status, ints) = inst.get_integer(&[vr(fmu, "integer_output")]);
    assert_eq!((status, ints[0]), (OK, int));
    let (status, flags) = inst.get_boolean(&[vr(fmu, "boolean_output")]);
    assert_eq!((status, flags[0]), (OK, i32::from(flag)));
    assert_eq!(inst.set_string(&[vr(fmu, "string_input")], &[text]), OK);
    let (status, texts) = inst.get_string(&[vr(fmu, "string_output")]);
    assert_eq!(
        (status, texts.as_slice()),
        (OK, [text.to_owned()].as_slice())
    );
}

#[test]
fn outputs_equal_inputs_before_any_step() {
    let fmu = fixture();
    let mut inst = fmu.instantiate("feedthrough", false);
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    assert_fed_through(&fmu, &inst, 1.5, -2.25, 7, true, "first");
    assert_eq!(inst.exit_init(), OK);
    assert_fed_through(&fmu, &inst, -3.0, 4.5, -11, false, "");
    assert_eq!(inst.do_step(1e-3), OK);
    assert_fed_through(&fmu, &inst, 1e300, -0.0, i32::MIN, true, "après un pas ✓");
}

#[test]
fn calculated_parameter_and_locals() {
    let fmu = fixture();
    let mut inst = fmu.instantiate("locals", false);
    assert_eq!(inst.setup(2.5), OK);
    assert_eq!(inst.enter_init(), OK);
    let gain = vr(&fmu, "real_tunable_parameter");
    assert_eq!(inst.set_real(&[gain], &[2.0]), OK);
    assert_eq!(inst.exit_init(), OK);
    assert_eq!(inst.get_real_one(vr(&fmu, "start_time")), 2.5);
    let input = vr(&fmu, "real_continuous_input");
    assert_eq!(inst.set_real(&[input], &[3.0]), OK);
    for _ in 0..4 {
        let status = inst.do_step(0.25);
        assert!(status == OK || status == WARNING, "{:#?}", inst.take_log());
    }
    // 2 (gain) x 3 (input) x 1 s, exactly representable.
    assert_eq!(inst.get_real_one(vr(&fmu, "real_continuous_local")), 6.0);
    let (status, steps) = inst.get_integer(&[vr(&fmu, "integer_discrete_local")]);
    assert_eq!((status, steps[0]), (OK, 4));
    // The tunable Boolean holds the integral.
    assert_eq!(
        inst.set_boolean(&[vr(&fmu, "boolean_tunable_parameter")], &[true]),
        OK
    );
    assert_eq!(inst.do_step(0.25), OK);
    assert_eq!(inst.get_real_one(vr(&fmu, "real_continuous_local")), 6.0);
    // A reset brings back the start values.
    assert_eq!(inst.reset(), OK);
    inst.initialize();
    assert_eq!(inst.get_real_one(gain), 1.0);
    assert_eq!(inst.get_real_one(vr(&fmu, "real_continuous_local")), 0.0);
    assert_eq!(inst.get_real_one(vr(&fmu, "real_continuous_output")), 0.0);
}

#[test]
fn the_string_parameter_time_and_constant() {
    let fmu = fixture();
    let mut inst = fmu.instantiate("time", false);
    assert_eq!(inst.setup(0.5), OK);
    assert_eq!(inst.enter_init(), OK);
    let parameter = vr(&fmu, "string_fixed_parameter");
    assert_eq!(
        inst.get_string(&[parameter]).1,
        [STRING_PARAMETER_START.to_owned()]
    );
    assert_eq!(inst.set_string(&[parameter], &["set before the run"]), OK);
    assert_eq!(inst.exit_init(), OK);
    let (time, constant) = (vr(&fmu, "time"), vr(&fmu, "real_constant_output"));
    assert_eq!(inst.get_real_one(time), 0.5);
    for k in 1..=4 {
        assert_eq!(inst.do_step(0.125), OK);
        assert_eq!(inst.get_real_one(time), 0.5 + 0.125 * f64::from(k));
        assert_eq!(inst.get_real_one(constant), REAL_CONSTANT);
    }
    assert_eq!(
        inst.get_string(&[parameter]).1,
        ["set before the run".to_owned()]
    );
    // The constant is declared with its value.
    assert_eq!(
        fmu.variable("real_constant_output").start,
        Some(REAL_CONSTANT)
    );
}
