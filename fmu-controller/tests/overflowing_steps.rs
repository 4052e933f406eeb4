//! A step that the control law cannot compute (a huge communication step
//! overflows the PI integrators) fails with fmi2Error and a message instead
//! of returning fmi2OK with NaN or infinite commands for the stage.

use fmi2_conformance::{ERROR, Fmu, OK};
use fmu_controller::PiezoControllerFmu;

fn controller() -> Fmu {
    fmi2_conformance::workspace::load::<PiezoControllerFmu>("fmu-controller")
}

#[test]
fn a_step_that_overflows_the_integrators_is_an_error() {
    let fmu = controller();
    let x_ref = fmu.variable("x_ref").vr;
    let mut inst = fmu.instantiate("overflow", false);
    inst.initialize();
    // A tracking error the integrators accumulate over the step.
    assert_eq!(inst.set_real(&[x_ref], &[5.0]), OK);
    assert_eq!(inst.do_step(1e-4), OK);
    assert_eq!(inst.do_step(f64::MAX), ERROR);
    let log = inst.take_log();
    assert!(
        log.iter().any(
            |r| r.message.starts_with("fmi2DoStep") && r.message.contains("cannot be computed")
        ),
        "{log:#?}"
    );
}
