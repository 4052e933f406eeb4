//! FMU state: snapshots of an instance (`fmi2GetFMUstate`) and their byte form
//! (`fmi2SerializeFMUstate`).
//!
//! A snapshot holds values, never pointers: the model value (serde), the time,
//! the start time, the interface and the state of the FMI state machine the
//! instance was in. Restoring it restores all of them: an instance restarts
//! where the snapshot was taken, state machine included (see
//! `Instance::restore`). The byte form is
//!
//! ```text
//! magic "FMI2RSST" | format version u32 LE | GUID (38 ASCII bytes)
//! | payload length u64 LE | payload (postcard) | CRC-32 of all preceding bytes, u32 LE
//! ```
//!
//! so that a state written by one process restores in another, and truncated or
//! corrupted bytes, or bytes of another model, are refused with a reason.

use serde::{Deserialize, Serialize, de::DeserializeOwned};

use crate::status::{FmiState, Interface};

const FILE_MAGIC: &[u8; 8] = b"FMI2RSST";
/// 2: the snapshot carries the start time, the interface and the machine
/// state (version 1 carried an "initialized" flag instead). 3: the machine
/// states of asynchronous steps are gone (the state's encoding changed) and
/// the snapshot carries whether the model asked to terminate. 4: the
/// snapshot carries the stop time.
const FORMAT_VERSION: u32 = 4;
const GUID_LEN: usize = 38;
const HEADER_LEN: usize = FILE_MAGIC.len() + 4 + GUID_LEN + 8;
const CRC_LEN: usize = 4;

/// The values of an instance that an FMU state captures.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SnapshotData<M> {
    pub model: M,
    pub time: f64,
    /// The `startTime` of `fmi2SetupExperiment` (0 until it is called).
    pub start_time: f64,
    /// Its `stopTime`, infinite when it defined none. A state taken before
    /// initialization brings both times back; after it, a restore keeps the
    /// receiving instance's own: they are its importer's statement about its
    /// run (FMI 2.0.4 §2.1.6), which continues from the state.
    pub stop_time: f64,
    /// The interface of the instance it was taken from.
    pub interface: Interface,
    /// The state of the FMI state machine it was taken in.
    pub state: FmiState,
    /// Whether the model had asked to end the simulation (a discarded step,
    /// `fmi2Terminated`).
    pub terminate_requested: bool,
}

/// What `fmi2FMUstate` points to; `repr(C)` with the magic number first (see
/// `Instance`; the number is model `M`'s, `instance::Magic`).
#[repr(C)]
pub(crate) struct Snapshot<M> {
    pub(crate) magic: u64,
    pub(crate) data: SnapshotData<M>,
    /// Bytes computed by `fmi2SerializedFMUstateSize`, reused by
    /// `fmi2SerializeFMUstate` so the state is encoded once.
    pub(crate) encoded: Option<Vec<u8>>,
    /// The instance that made it (`Instance<M>`), which frees it in
    /// `fmi2FreeInstance` unless the importer freed it before.
    pub(crate) owner: *mut std::ffi::c_void,
}

impl<M: crate::CoSimModel> Snapshot<M> {
    pub(crate) fn new(data: SnapshotData<M>, owner: *mut std::ffi::c_void) -> Snapshot<M> {
        Snapshot {
            magic: crate::instance::Magic::<M>::SNAPSHOT,
            data,
            encoded: None,
            owner,
        }
    }
}

/// Encodes a snapshot for `guid`.
pub fn encode<M: Serialize>(data: &SnapshotData<M>, guid: &str) -> Result<Vec<u8>, String> {
    if guid.len() != GUID_LEN {
        return Err(format!("GUID {guid} is not {GUID_LEN} characters long"));
    }
    let payload = postcard::to_stdvec(data).map_err(|e| format!("cannot encode the state: {e}"))?;
    let mut bytes = Vec::with_capacity(HEADER_LEN + payload.len() + CRC_LEN);
    bytes.extend_from_slice(FILE_MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(guid.as_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&payload);
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    Ok(bytes)
}

/// Decodes bytes written by [`encode`] for the same `guid`, refusing anything
/// else with the reason.
pub fn decode<M: DeserializeOwned>(bytes: &[u8], guid: &str) -> Result<SnapshotData<M>, String> {
    if bytes.len() < HEADER_LEN + CRC_LEN {
        return Err(format!(
            "{} bytes is shorter than the {}-byte header of a serialized state (truncated?)",
            bytes.len(),
            HEADER_LEN + CRC_LEN
        ));
    }
    if &bytes[..8] != FILE_MAGIC {
        return Err("the bytes are not a serialized state of this FMU (wrong magic)".into());
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != FORMAT_VERSION {
        return Err(format!(
            "serialized state format version {version} is not supported (expected {FORMAT_VERSION})"
        ));
    }
    let stored_guid = &bytes[12..12 + GUID_LEN];
    if stored_guid != guid.as_bytes() {
        return Err(format!(
            "the state belongs to a model with GUID {} but this FMU's GUID is {guid}",
            String::from_utf8_lossy(stored_guid)
        ));
    }
    let payload_len = u64::from_le_bytes(
        bytes[12 + GUID_LEN..HEADER_LEN]
            .try_into()
            .expect("8 bytes"),
    );
    let expected = (HEADER_LEN as u64)
        .checked_add(payload_len)
        .and_then(|n| n.checked_add(CRC_LEN as u64));
    if expected != Some(bytes.len() as u64) {
        return Err(format!(
            "the header announces a {payload_len}-byte payload but {} bytes were given (truncated or padded)",
            bytes.len()
        ));
    }
    let (body, crc_bytes) = bytes.split_at(bytes.len() - CRC_LEN);
    let stored_crc = u32::from_le_bytes(crc_bytes.try_into().expect("4 bytes"));
    let crc = crc32fast::hash(body);
    if crc != stored_crc {
        return Err(format!(
            "checksum mismatch (stored {stored_crc:#010x}, computed {crc:#010x}): the bytes are corrupted"
        ));
    }
    postcard::from_bytes(&body[HEADER_LEN..]).map_err(|e| format!("cannot decode the state: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GUID: &str = "{01234567-89ab-cdef-0123-456789abcdef}";

    fn sample() -> SnapshotData<Vec<f64>> {
        SnapshotData {
            model: vec![1.0, -0.1, f64::MIN_POSITIVE, 1e300],
            time: 0.123,
            start_time: -2.5,
            stop_time: f64::INFINITY,
            interface: Interface::ModelExchange,
            state: FmiState::ContinuousTimeMode,
            terminate_requested: false,
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let bytes = encode(&sample(), GUID).unwrap();
        let back: SnapshotData<Vec<f64>> = decode(&bytes, GUID).unwrap();
        assert_eq!(back, sample());
    }

    #[test]
    fn every_truncation_is_refused() {
        let bytes = encode(&sample(), GUID).unwrap();
        for n in 0..bytes.len() {
            assert!(decode::<Vec<f64>>(&bytes[..n], GUID).is_err(), "length {n}");
        }
    }

    #[test]
    fn every_single_bit_flip_is_refused() {
        let bytes = encode(&sample(), GUID).unwrap();
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut corrupted = bytes.clone();
                corrupted[i] ^= 1 << bit;
                assert!(
                    decode::<Vec<f64>>(&corrupted, GUID).is_err(),
                    "byte {i} bit {bit}"
                );
            }
        }
    }

    #[test]
    fn another_models_state_is_refused() {
        let bytes = encode(&sample(), GUID).unwrap();
        let other = "{11111111-89ab-cdef-0123-456789abcdef}";
        let err = decode::<Vec<f64>>(&bytes, other).unwrap_err();
        assert!(err.contains("GUID"), "{err}");
    }
}
