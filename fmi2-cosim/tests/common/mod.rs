//! What the integration tests share: an instance of a test model driven
//! through the layer's C entry points (`abi`), as an importer drives it, and
//! the forging of serialized FMU states. Each test file uses part of it.
#![allow(dead_code)]

use std::ffi::CString;
use std::marker::PhantomData;
use std::ptr;

use fmi2_cosim::CoSimModel;
use fmi2_cosim::abi;
use fmi2_cosim::fmi_sys::fmi2 as sys;

pub const OK: sys::fmi2Status = sys::fmi2Status_fmi2OK;
pub const WARNING: sys::fmi2Status = sys::fmi2Status_fmi2Warning;
pub const DISCARD: sys::fmi2Status = sys::fmi2Status_fmi2Discard;
pub const ERROR: sys::fmi2Status = sys::fmi2Status_fmi2Error;

/// A co-simulation instance of `M` without a logger, freed on drop.
pub struct Slave<M: CoSimModel>(pub sys::fmi2Component, PhantomData<M>);

impl<M: CoSimModel> Slave<M> {
    pub fn instantiate() -> Self {
        let callbacks = sys::fmi2CallbackFunctions {
            logger: None,
            allocateMemory: None,
            freeMemory: None,
            stepFinished: None,
            componentEnvironment: ptr::null_mut(),
        };
        let guid = CString::new(fmi2_cosim::model_description::guid::<M>().unwrap()).unwrap();
        // SAFETY: every pointer is valid for the call; the GUID and the
        // callbacks outlive it (the layer copies what it keeps).
        let c = unsafe {
            abi::instantiate::<M>(
                c"slave".as_ptr(),
                sys::fmi2Type_fmi2CoSimulation,
                guid.as_ptr(),
                ptr::null(),
                &callbacks,
                0,
                0,
            )
        };
        assert!(!c.is_null());
        Slave(c, PhantomData)
    }

    /// fmi2SetupExperiment at `start` and fmi2EnterInitializationMode.
    pub fn setup_and_enter(&self, start: f64) {
        // SAFETY: `self.0` is a live instance of M.
        unsafe {
            assert_eq!(
                abi::setup_experiment::<M>(self.0, 0, 0.0, start, 0, 0.0),
                OK
            );
            assert_eq!(abi::enter_initialization_mode::<M>(self.0), OK);
        }
    }

    pub fn exit_initialization(&self) -> sys::fmi2Status {
        // SAFETY: `self.0` is a live instance of M.
        unsafe { abi::exit_initialization_mode::<M>(self.0) }
    }

    pub fn set_real(&self, vr: u32, value: f64) -> sys::fmi2Status {
        // SAFETY: one value reference and one value, both on the stack.
        unsafe { abi::set_real::<M>(self.0, &vr, 1, &value) }
    }

    pub fn get_real(&self, vr: u32) -> (sys::fmi2Status, f64) {
        let mut value = f64::NAN;
        // SAFETY: as in `set_real`.
        let status = unsafe { abi::get_real::<M>(self.0, &vr, 1, &mut value) };
        (status, value)
    }

    /// The value of `vr`, read with fmi2OK.
    pub fn real(&self, vr: u32) -> f64 {
        let (status, value) = self.get_real(vr);
        assert_eq!(status, OK);
        value
    }

    pub fn set_integer(&self, vr: u32, value: i32) -> sys::fmi2Status {
        // SAFETY: as in `set_real`.
        unsafe { abi::set_integer::<M>(self.0, &vr, 1, &value) }
    }

    pub fn get_integer(&self, vr: u32) -> (sys::fmi2Status, i32) {
        let mut value = i32::MIN;
        // SAFETY: as in `set_real`.
        let status = unsafe { abi::get_integer::<M>(self.0, &vr, 1, &mut value) };
        (status, value)
    }

    pub fn step(&self, t: f64, h: f64) -> sys::fmi2Status {
        // SAFETY: `self.0` is a live instance of M.
        unsafe { abi::do_step::<M>(self.0, t, h, 1) }
    }

    pub fn last_successful_time(&self) -> (sys::fmi2Status, f64) {
        let mut time = f64::NAN;
        // SAFETY: `time` is valid for a write.
        let status = unsafe {
            abi::get_real_status::<M>(
                self.0,
                sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                &mut time,
            )
        };
        (status, time)
    }

    pub fn terminated(&self) -> (sys::fmi2Status, sys::fmi2Boolean) {
        let mut flag = -1;
        // SAFETY: `flag` is valid for a write.
        let status = unsafe {
            abi::get_boolean_status::<M>(self.0, sys::fmi2StatusKind_fmi2Terminated, &mut flag)
        };
        (status, flag)
    }

    pub fn terminate(&self) -> sys::fmi2Status {
        // SAFETY: `self.0` is a live instance of M.
        unsafe { abi::terminate::<M>(self.0) }
    }

    pub fn reset(&self) -> sys::fmi2Status {
        // SAFETY: `self.0` is a live instance of M.
        unsafe { abi::reset::<M>(self.0) }
    }

    pub fn get_state(&self) -> sys::fmi2FMUstate {
        let mut state: sys::fmi2FMUstate = ptr::null_mut();
        // SAFETY: `state` is a NULL slot the layer fills.
        let status = unsafe { abi::get_fmu_state::<M>(self.0, &mut state) };
        assert_eq!(status, OK);
        state
    }

    pub fn set_state(&self, state: sys::fmi2FMUstate) -> sys::fmi2Status {
        // SAFETY: `state` was made by this layer for M, or is refused.
        unsafe { abi::set_fmu_state::<M>(self.0, state) }
    }

    pub fn serialize(&self, state: sys::fmi2FMUstate) -> Vec<u8> {
        let mut size = 0;
        // SAFETY: `state` is a live state of this instance; the buffer has
        // the size the layer asked for.
        unsafe {
            assert_eq!(
                abi::serialized_fmu_state_size::<M>(self.0, state, &mut size),
                OK
            );
            let mut bytes = vec![0u8; size];
            assert_eq!(
                abi::serialize_fmu_state::<M>(self.0, state, bytes.as_mut_ptr().cast(), size),
                OK
            );
            bytes
        }
    }

    /// Deserializes `bytes` into a new FMU state: the status and the state.
    pub fn deserialize(&self, bytes: &[u8]) -> (sys::fmi2Status, sys::fmi2FMUstate) {
        let mut state: sys::fmi2FMUstate = ptr::null_mut();
        // SAFETY: `bytes` is a live slice; `state` a NULL slot.
        let status = unsafe {
            abi::deserialize_fmu_state::<M>(self.0, bytes.as_ptr().cast(), bytes.len(), &mut state)
        };
        (status, state)
    }
}

impl<M: CoSimModel> Drop for Slave<M> {
    fn drop(&mut self) {
        // SAFETY: `self.0` is live; freeing it frees its FMU states too.
        unsafe { abi::free_instance::<M>(self.0) };
    }
}

/// Header (magic, version, GUID, payload length) and trailer (CRC-32) of a
/// serialized state: `fmu_state`'s documented byte form.
const HEADER_LEN: usize = 8 + 4 + 38 + 8;
const CRC_LEN: usize = 4;

/// `bytes` with the one occurrence of `from` in the payload replaced by `to`
/// (as long), and the checksum recomputed: bytes written on purpose.
pub fn forge(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let mut out = bytes.to_vec();
    let payload = HEADER_LEN..out.len() - CRC_LEN;
    let hits: Vec<usize> = out[payload.clone()]
        .windows(from.len())
        .enumerate()
        .filter(|(_, w)| *w == from)
        .map(|(i, _)| HEADER_LEN + i)
        .collect();
    assert_eq!(hits.len(), 1, "{from:?} occurs {} times", hits.len());
    out[hits[0]..hits[0] + from.len()].copy_from_slice(to);
    let crc = crc32fast::hash(&out[..payload.end]);
    out[payload.end..].copy_from_slice(&crc.to_le_bytes());
    out
}
