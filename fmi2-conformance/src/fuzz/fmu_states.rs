//! FMU states: get, set, free, serialize and deserialize, with intact,
//! corrupted, forged and foreign states and bytes.

use super::*;

impl Fuzzer<'_> {
    pub(super) fn get_fmu_state(&mut self, slot: usize, benign: bool) {
        enum Target {
            Fresh,
            Reuse(usize),
            Null,
            Foreign,
        }
        let target = match self.rng.random_range(0..20) {
            _ if self.handles.len() >= MAX_HANDLES => {
                Target::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            0..13 => Target::Fresh,
            13..16 if !self.handles.is_empty() => {
                Target::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            16 if !benign => Target::Null,
            17..19 if !benign => Target::Foreign,
            _ => Target::Fresh,
        };
        let mut state_slot: sys::fmi2FMUstate = match target {
            Target::Reuse(i) => self.handles[i].ptr,
            Target::Foreign => self.state_argument(0.0).1,
            _ => ptr::null_mut(),
        };
        let before = state_slot;
        let valid = match target {
            Target::Fresh | Target::Reuse(_) => true,
            // NULL is the fresh case: only a non-NULL foreign pointer is wrong.
            Target::Foreign => before.is_null(),
            Target::Null => false,
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::Get));
        self.begin("fmi2GetFMUstate", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu.binding.fmi2GetFMUstate(
                c,
                if matches!(target, Target::Null) {
                    ptr::null_mut()
                } else {
                    &mut state_slot
                },
            )
        };
        let allowed = if is_legal && valid { [OK] } else { [ERROR] };
        self.check(slot, "fmi2GetFMUstate", status, &allowed, !is_legal, || {
            format!("*FMUstate {before:?}")
        });
        if status != OK {
            if state_slot != before {
                self.fail("fmi2GetFMUstate failed but changed *FMUstate".to_owned());
            }
            return;
        }
        let mut model = self.live(slot).model.clone();
        model.machine = self.live(slot).state;
        match target {
            Target::Reuse(i) => {
                if state_slot != before {
                    self.fail("fmi2GetFMUstate did not reuse the state it was given".to_owned());
                }
                self.handles[i].model = model;
            }
            _ => {
                if state_slot.is_null() {
                    self.fail("fmi2GetFMUstate returned OK and no state".to_owned());
                }
                self.handles.push(Handle {
                    ptr: state_slot,
                    owner: slot,
                    model,
                });
            }
        }
    }

    /// `fmi2SetFMUstate`: a state of this FMU restores the values and the
    /// machine state it was taken in, from whatever state the instance is in
    /// (error state included); a state of the other interface is refused.
    pub(super) fn set_fmu_state(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.85 });
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::Set));
        let interface = self.live(slot).model.interface;
        let same_interface = own.is_some_and(|i| self.handles[i].model.interface == interface);
        // A forged state may claim anything, its interface and machine state
        // included.
        let forged = own.is_some_and(|i| self.handles[i].model.tainted);
        let allowed: &[sys::fmi2Status] = if !is_legal || own.is_none() {
            &[ERROR]
        } else if forged {
            &[OK, ERROR]
        } else if same_interface {
            &[OK]
        } else {
            &[ERROR]
        };
        self.begin("fmi2SetFMUstate", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe { self.fmu.binding.fmi2SetFMUstate(c, state) };
        let log = self.check(slot, "fmi2SetFMUstate", status, allowed, !is_legal, || {
            format!("own state {own:?}, same interface {same_interface}, forged {forged}")
        });
        // A forged state was checked when it was deserialized: the only claim
        // left to refuse it for is the other interface, and the refusal says so.
        if status != OK && is_legal && own.is_some() && (forged || !same_interface) {
            let live = self.live(slot);
            if live.has_logger && !log.iter().any(|r| r.message.contains("interface")) {
                self.fail(format!(
                    "a state refused for a reason other than its interface (forged {forged}): \
                     {log:#?}"
                ));
            }
        }
        if status == OK {
            self.report.states_restored += 1;
            let model = self.handles[own.expect("only own states restore")]
                .model
                .clone();
            let model_machine = model.machine;
            let live = self.live_mut(slot);
            live.state = model.machine;
            // The interface is the instance's: a forged state may claim the
            // other one and still be accepted. After initialization, so are
            // the start and stop times, which the importer set up for this
            // instance's experiment; a state from before it brings its own.
            let own = (live.model.start_time, live.model.stop_time);
            let interface = live.model.interface;
            live.model = model;
            live.model.interface = interface;
            if !matches!(
                model_machine,
                State::Instantiated | State::InitializationMode
            ) {
                (live.model.start_time, live.model.stop_time) = own;
            }
            if forged {
                // The machine state a forged state put the instance in is
                // unknown: a reset brings it back to a known one.
                self.simple(slot, Simple::Reset);
            }
        }
    }

    pub(super) fn free_fmu_state(&mut self, slot: usize, benign: bool) {
        let choice = if benign {
            0
        } else {
            self.rng.random_range(0..10)
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::Free));
        match choice {
            0..6 if !self.handles.is_empty() => {
                let index = self.rng.random_range(0..self.handles.len());
                if is_legal {
                    return self.free_handle(slot, index);
                }
                let mut pointer = self.handles[index].ptr;
                self.begin("fmi2FreeFMUstate", Some(slot));
                // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or
                // holds at least the length passed with it, and each FMU-state argument is
                // NULL, a live state of this FMU, or an object the module documentation lists,
                // which the layer must refuse.
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut pointer) };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &[ERROR],
                    true,
                    String::new,
                );
            }
            6 => {
                let mut null_state: sys::fmi2FMUstate = ptr::null_mut();
                self.begin("fmi2FreeFMUstate", Some(slot));
                // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or
                // holds at least the length passed with it, and each FMU-state argument is
                // NULL, a live state of this FMU, or an object the module documentation lists,
                // which the layer must refuse.
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut null_state) };
                let allowed = if is_legal { [OK] } else { [ERROR] };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &allowed,
                    !is_legal,
                    || "*FMUstate NULL".to_owned(),
                );
            }
            7 => {
                self.begin("fmi2FreeFMUstate", Some(slot));
                // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or
                // holds at least the length passed with it, and each FMU-state argument is
                // NULL, a live state of this FMU, or an object the module documentation lists,
                // which the layer must refuse.
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, ptr::null_mut()) };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &[ERROR],
                    !is_legal,
                    || "FMUstate NULL".to_owned(),
                );
            }
            _ => {
                let (_, mut foreign) = self.state_argument(0.0);
                let before = foreign;
                self.begin("fmi2FreeFMUstate", Some(slot));
                // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or
                // holds at least the length passed with it, and each FMU-state argument is
                // NULL, a live state of this FMU, or an object the module documentation lists,
                // which the layer must refuse.
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut foreign) };
                let allowed = if is_legal && before.is_null() {
                    [OK]
                } else {
                    [ERROR]
                };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &allowed,
                    !is_legal,
                    || format!("*FMUstate {before:?}, not a state of this FMU"),
                );
                if foreign != before {
                    self.fail("fmi2FreeFMUstate changed a pointer it refused".to_owned());
                }
            }
        }
    }

    pub(super) fn serialized_size(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.85 });
        let null_size = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::SerializedSize));
        let mut size = usize::MAX;
        self.begin("fmi2SerializedFMUstateSize", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu.binding.fmi2SerializedFMUstateSize(
                c,
                state,
                if null_size {
                    ptr::null_mut()
                } else {
                    &mut size
                },
            )
        };
        let allowed = if is_legal && own.is_some() && !null_size {
            [OK]
        } else {
            [ERROR]
        };
        self.check(
            slot,
            "fmi2SerializedFMUstateSize",
            status,
            &allowed,
            !is_legal,
            || format!("own state {own:?}, NULL size {null_size}"),
        );
        if status == OK && (size == 0 || size == usize::MAX) {
            self.fail(format!("fmi2SerializedFMUstateSize answered {size}"));
        }
    }

    /// fmi2SerializedFMUstateSize, then fmi2SerializeFMUstate with that size
    /// or a wrong one.
    pub(super) fn serialize(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.9 });
        let c = self.live(slot).c;
        let state_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::Serialize));
        let mut needed = 0usize;
        if own.is_some() && state_legal {
            self.begin("fmi2SerializedFMUstateSize", Some(slot));
            // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds
            // at least the length passed with it, and each FMU-state argument is NULL, a live
            // state of this FMU, or an object the module documentation lists, which the layer
            // must refuse.
            let status = unsafe {
                self.fmu
                    .binding
                    .fmi2SerializedFMUstateSize(c, state, &mut needed)
            };
            self.check(
                slot,
                "fmi2SerializedFMUstateSize",
                status,
                &[OK],
                false,
                String::new,
            );
        } else {
            needed = self.rng.random_range(0..256);
        }
        let size = match self.rng.random_range(0..20) {
            _ if benign => needed,
            0 => needed.saturating_sub(1),
            1 => needed + 1,
            2 => 0,
            _ => needed,
        };
        let null_buffer = !benign && self.chance(0.04);
        let mut buffer = vec![0u8; size.max(1)];
        self.begin("fmi2SerializeFMUstate", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu.binding.fmi2SerializeFMUstate(
                c,
                state,
                if null_buffer {
                    ptr::null_mut()
                } else {
                    buffer.as_mut_ptr().cast()
                },
                size,
            )
        };
        let valid = own.is_some() && size == needed && !null_buffer;
        let allowed = if state_legal && valid { [OK] } else { [ERROR] };
        self.check(
            slot,
            "fmi2SerializeFMUstate",
            status,
            &allowed,
            !state_legal,
            || format!("own state {own:?}, size {size} of {needed}, NULL buffer {null_buffer}"),
        );
        if status == OK {
            buffer.truncate(size);
            let blob = Blob {
                bytes: buffer,
                model: self.handles[own.expect("own")].model.clone(),
            };
            if self.blobs.len() >= MAX_BLOBS {
                let i = self.rng.random_range(0..self.blobs.len());
                self.blobs[i] = blob;
            } else {
                self.blobs.push(blob);
            }
        }
    }

    pub(super) fn deserialize(&mut self, slot: usize, benign: bool) {
        #[derive(Debug, PartialEq)]
        enum Source {
            Intact(usize),
            Corrupted,
            Foreign,
            Forged(usize),
            NullWithSize,
            NullEmpty,
        }
        let choice = if benign {
            0
        } else {
            self.rng.random_range(0..100)
        };
        let (source, bytes) = match choice {
            0..45 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                (Source::Intact(i), self.blobs[i].bytes.clone())
            }
            45..80 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                let original = self.blobs[i].bytes.clone();
                (Source::Corrupted, self.corrupt(&original))
            }
            80..88 if self.foreign.is_some() => (
                Source::Foreign,
                self.foreign.as_ref().unwrap().bytes.clone(),
            ),
            88..94 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                let original = self.blobs[i].bytes.clone();
                if original.len() <= STATE_HEADER_LEN + STATE_CRC_LEN {
                    self.fail(format!(
                        "a serialized state of {} bytes has no payload",
                        original.len()
                    ));
                }
                (Source::Forged(i), self.forge(&original))
            }
            94..97 => (Source::NullWithSize, Vec::new()),
            97..100 => (Source::NullEmpty, Vec::new()),
            _ => {
                let n = self.rng.random_range(0..200);
                (
                    Source::Corrupted,
                    (0..n).map(|_| self.rng.random::<u8>()).collect(),
                )
            }
        };
        // FMUstate is output only (FMI 2.0.4 §2.1.8): a state this instance
        // made is reused; whatever else *FMUstate holds (a state of another
        // instance, a foreign object) is overwritten with a new state, and
        // left as it was.
        enum Out {
            Fresh,
            Reuse(usize),
            Null,
            Foreign,
        }
        let own: Vec<usize> = (0..self.handles.len())
            .filter(|i| self.handles[*i].owner == slot)
            .collect();
        let out = match self.rng.random_range(0..20) {
            _ if self.handles.len() >= MAX_HANDLES => match own.is_empty() {
                false => Out::Reuse(own[self.rng.random_range(0..own.len())]),
                true => Out::Null,
            },
            _ if benign => Out::Fresh,
            0..15 => Out::Fresh,
            15..17 if !self.handles.is_empty() => {
                Out::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            17 => Out::Null,
            18 => Out::Foreign,
            _ => Out::Fresh,
        };
        let mut state_slot: sys::fmi2FMUstate = match out {
            Out::Reuse(i) => self.handles[i].ptr,
            Out::Foreign => self.state_argument(0.0).1,
            _ => ptr::null_mut(),
        };
        let before = state_slot;
        let out_valid = !matches!(out, Out::Null);
        let reused = match out {
            Out::Reuse(i) => own.contains(&i).then_some(i),
            _ => None,
        };
        let (data, size): (*const sys::fmi2Byte, usize) = match source {
            Source::NullWithSize => (ptr::null(), self.rng.random_range(1..1000)),
            Source::NullEmpty => (ptr::null(), 0),
            _ => (bytes.as_ptr().cast(), bytes.len()),
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, Function::FmuState(FmuStateCall::DeSerialize));
        let allowed: &[sys::fmi2Status] = if !is_legal || !out_valid {
            &[ERROR]
        } else {
            match source {
                Source::Intact(_) => &[OK],
                Source::Forged(_) => &[OK, ERROR],
                _ => &[ERROR],
            }
        };
        self.begin("fmi2DeSerializeFMUstate", Some(slot));
        // SAFETY: `c` is the live instance in `slot`; each array argument is NULL or holds at
        // least the length passed with it, and each FMU-state argument is NULL, a live state of
        // this FMU, or an object the module documentation lists, which the layer must refuse.
        let status = unsafe {
            self.fmu.binding.fmi2DeSerializeFMUstate(
                c,
                data,
                size,
                if matches!(out, Out::Null) {
                    ptr::null_mut()
                } else {
                    &mut state_slot
                },
            )
        };
        let log = self.check(
            slot,
            "fmi2DeSerializeFMUstate",
            status,
            allowed,
            !is_legal,
            || format!("{source:?}, {size} bytes, *FMUstate {before:?}"),
        );
        if status != OK {
            if state_slot != before {
                self.fail("fmi2DeSerializeFMUstate failed but changed *FMUstate".to_owned());
            }
            let corrupted = matches!(
                source,
                Source::Corrupted | Source::Foreign | Source::Forged(_)
            );
            if is_legal && out_valid && corrupted {
                self.report.corrupted_states_refused += 1;
                if self.live(slot).has_logger && !log.iter().any(|r| r.message.contains("refused"))
                {
                    self.fail(format!(
                        "corrupted bytes refused without saying so: {log:#?}"
                    ));
                }
            }
            return;
        }
        // `check` let OK through for intact and forged bytes only.
        let (Source::Intact(i) | Source::Forged(i)) = source else {
            self.fail(format!("fmi2DeSerializeFMUstate accepted {source:?}"));
        };
        let mut model = self.blobs[i].model.clone();
        if matches!(source, Source::Forged(_)) {
            self.report.forged_states_accepted += 1;
            model.tainted = true;
        }
        match reused {
            Some(i) => {
                if state_slot != before {
                    self.fail(
                        "fmi2DeSerializeFMUstate did not reuse the state it was given".to_owned(),
                    );
                }
                self.handles[i].model = model;
            }
            None => {
                if state_slot.is_null() {
                    self.fail("fmi2DeSerializeFMUstate returned OK and no state".to_owned());
                }
                if !before.is_null() && state_slot == before {
                    self.fail(format!(
                        "fmi2DeSerializeFMUstate wrote into {before:?}, not a state of its instance"
                    ));
                }
                self.handles.push(Handle {
                    ptr: state_slot,
                    owner: slot,
                    model,
                });
            }
        }
    }
}
