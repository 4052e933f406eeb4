//! The generator: random choices of functions, values, value references,
//! pointers and bytes, mostly plausible and often hostile.

use super::*;

impl Fuzzer<'_> {
    pub(super) fn chance(&mut self, p: f64) -> bool {
        self.rng.random_bool(p)
    }

    pub(super) fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.rng.random_range(0..items.len())]
    }

    /// A function by weight: among the legal ones three times in four.
    pub(super) fn pick_function(&mut self, interface: Interface, state: State) -> Function {
        let only_legal = self.chance(0.75);
        let candidates: Vec<(Function, u32)> = self
            .functions()
            .filter(|(f, _)| !only_legal || legal(interface, *f, state))
            .collect();
        let total: u32 = candidates.iter().map(|(_, w)| w).sum();
        let mut x = self.rng.random_range(0..total);
        // The last candidate takes whatever the others leave: x < total.
        let (last, others) = candidates.split_last().expect("freeing is always legal");
        for &(function, weight) in others {
            if x < weight {
                return function;
            }
            x -= weight;
        }
        last.0
    }

    /// A Real value for variable `index`: mostly plausible, often hostile.
    pub(super) fn real_value(&mut self, index: usize, current: Option<f64>) -> f64 {
        let start = self.fmu.variables[index].start.unwrap_or(0.0);
        match self.rng.random_range(0..100) {
            0..22 => current.unwrap_or(start),
            22..34 => start,
            34..48 => start * self.rng.random_range(0.5..2.0),
            48..60 => self.rng.random_range(-10.0..10.0),
            60..64 => self.pick(&[0.0, -0.0]),
            64..70 => self.pick(&[1e15, -1e15, 1e300, -1e300, f64::MAX, f64::MIN]),
            70..74 => self.pick(&[5e-324, -5e-324, f64::MIN_POSITIVE / 2.0, f64::MIN_POSITIVE]),
            74..79 => f64::from_bits(0x7ff8_0000_0000_0000 | self.rng.random_range(0..1u64 << 51)),
            79..84 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
            84..90 => f64::from_bits(self.rng.random()),
            _ => -start.abs() - self.rng.random_range(0.0..10.0),
        }
    }

    pub(super) fn integer_value(&mut self, index: usize, current: Option<f64>) -> i32 {
        let start = self.fmu.variables[index].start.unwrap_or(0.0) as i32;
        match self.rng.random_range(0..10) {
            0..3 => current.map_or(start, |v| v as i32),
            3..5 => start,
            5 => self.pick(&[0, 1, 2, 3, -1]),
            6 => self.pick(&[i32::MIN, i32::MAX]),
            _ => self.rng.random(),
        }
    }

    pub(super) fn boolean_value(&mut self, current: Option<f64>) -> sys::fmi2Boolean {
        match self.rng.random_range(0..10) {
            0..4 => current.map_or(0, |v| v as sys::fmi2Boolean),
            4..6 => 0,
            6..8 => 1,
            // Not fmi2True but true in C.
            _ => self.pick(&[2, -1, i32::MAX]),
        }
    }

    /// A String argument for variable `index`: `None` for a NULL pointer,
    /// else the bytes before the terminating NUL (none inside): mostly
    /// plausible text, often markup, characters outside ASCII or long, and
    /// sometimes bytes that are not UTF-8.
    pub(super) fn string_value(
        &mut self,
        index: Option<usize>,
        current: Option<&str>,
    ) -> Option<Vec<u8>> {
        let start = index
            .and_then(|i| self.fmu.variables[i].start_string.clone())
            .unwrap_or_default();
        let text: Vec<u8> = match self.rng.random_range(0..100) {
            0..20 => current.map_or(start, str::to_owned).into_bytes(),
            20..30 => start.into_bytes(),
            30..45 => {
                let n = self.rng.random_range(1..24);
                (0..n).map(|_| self.rng.random_range(b' '..=b'~')).collect()
            }
            45..55 => Vec::new(),
            55..65 => self
                .pick(&[
                    "µ",
                    "✓ ok",
                    "日本語のテキスト",
                    "𝄞 clef",
                    "mixed ASCII и кириллица",
                ])
                .into(),
            65..72 => self
                .pick(&[
                    "<a href=\"x\">&amp;</a>",
                    "'quoted' \"twice\"",
                    "%s%d%n%%",
                    "tab\tnew\nline\r",
                ])
                .into(),
            72..78 => {
                let n = self.rng.random_range(256..8192);
                (0..n).map(|_| self.rng.random_range(b' '..=b'~')).collect()
            }
            // Control characters and DEL: C strings carry them.
            78..82 => (0..self.rng.random_range(1..8))
                .map(|_| self.pick(&[1u8, 7, 8, 27, 31, 127]))
                .collect(),
            // Not UTF-8: a lone continuation byte, an overlong NUL, an
            // encoded surrogate, a cut sequence, a byte never in UTF-8,
            // alone or inside text.
            82..90 => {
                let bad = self.pick(&[
                    &b"\x80"[..],
                    b"\xc0\x80",
                    b"\xed\xa0\x80",
                    b"\xe2\x82",
                    b"\xff",
                    b"\xf8\x88\x80\x80\x80",
                ]);
                let mut text = if self.chance(0.5) {
                    b"before ".to_vec()
                } else {
                    Vec::new()
                };
                text.extend_from_slice(bad);
                if self.chance(0.5) {
                    text.extend_from_slice(b" after");
                }
                text
            }
            90..97 => current.map_or(start, str::to_owned).into_bytes(),
            _ => return None,
        };
        Some(text)
    }

    /// Value references for a call on type `kind`.
    pub(super) fn vrs(&mut self, kind: &'static str, settable: bool) -> Vec<u32> {
        let n = match self.rng.random_range(0..20) {
            0..2 => 0,
            2..10 => 1,
            10..18 => self.rng.random_range(2..=8),
            _ => self.rng.random_range(9..=64),
        };
        let preferred = if settable {
            self.settable_by_kind.get(kind)
        } else {
            self.by_kind.get(kind)
        }
        .cloned()
        .unwrap_or_default();
        let everything: Vec<u32> = self.by_vr.keys().copied().collect();
        (0..n)
            .map(|_| match self.rng.random_range(0..100) {
                0..80 if !preferred.is_empty() => self.pick(&preferred),
                80..92 => self.pick(&everything),
                92..97 => {
                    let unknown = self.unknown_vrs.clone();
                    self.pick(&unknown)
                }
                _ => self.rng.random(),
            })
            .collect()
    }

    /// Which variable each vr names if all name a variable of `kind`;
    /// `Err(reason)` when the FMU must refuse.
    pub(super) fn resolve(&self, vrs: &[u32], kind: &str) -> Result<Vec<usize>, String> {
        vrs.iter()
            .map(|vr| match self.by_vr.get(vr) {
                None => Err(format!("unknown value reference {vr}")),
                Some(i) if self.fmu.variables[*i].kind != kind => Err(format!(
                    "value reference {vr} is {}, not {kind}",
                    self.fmu.variables[*i].kind
                )),
                Some(i) => Ok(*i),
            })
            .collect()
    }

    /// A pointer that is not an instance of the FMU under test.
    pub(super) fn not_an_instance(&mut self) -> (NotAnInstance, *mut c_void) {
        loop {
            let kind = self.pick(&[
                NotAnInstance::Null,
                NotAnInstance::OwnFmuState,
                NotAnInstance::ForeignInstance,
                NotAnInstance::ForeignFmuState,
                NotAnInstance::ZeroedMemory,
                NotAnInstance::RandomMemory,
            ]);
            let pointer = match kind {
                NotAnInstance::Null => ptr::null_mut(),
                NotAnInstance::OwnFmuState if !self.handles.is_empty() => {
                    self.handles[self.rng.random_range(0..self.handles.len())].ptr
                }
                NotAnInstance::ForeignInstance if self.foreign.is_some() => {
                    self.foreign.as_ref().unwrap().instance.c
                }
                NotAnInstance::ForeignFmuState if self.foreign.is_some() => {
                    self.foreign.as_ref().unwrap().state
                }
                NotAnInstance::ZeroedMemory => self.zeroed.as_mut_ptr().cast(),
                NotAnInstance::RandomMemory => self.random.as_mut_ptr().cast(),
                _ => continue,
            };
            return (kind, pointer);
        }
    }

    /// An FMU-state argument: one of ours (`Some(index)`) or something else.
    pub(super) fn state_argument(&mut self, own: f64) -> (Option<usize>, sys::fmi2FMUstate) {
        if !self.handles.is_empty() && self.chance(own) {
            let index = self.rng.random_range(0..self.handles.len());
            return (Some(index), self.handles[index].ptr);
        }
        let pointer = match self.rng.random_range(0..4) {
            0 => ptr::null_mut(),
            // An instance where a state belongs.
            1 => self
                .slots
                .iter()
                .flatten()
                .next()
                .map_or(ptr::null_mut(), |l| l.c),
            2 => self.foreign.as_ref().map_or(ptr::null_mut(), |f| f.state),
            _ => self.zeroed.as_mut_ptr().cast(),
        };
        (None, pointer)
    }

    /// Bytes that differ from a serialized state in a way a CRC-32 always
    /// detects (a burst of at most 32 bits), or in length, or entirely.
    pub(super) fn corrupt(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = bytes.to_vec();
        match self.rng.random_range(0..7) {
            0 if !out.is_empty() => {
                let i = self.rng.random_range(0..out.len());
                out[i] ^= 1 << self.rng.random_range(0..8);
            }
            1 if out.len() >= 4 => {
                let i = self.rng.random_range(0..out.len() - 3);
                let mask: u32 = self.rng.random_range(1..=u32::MAX);
                for (k, m) in mask.to_le_bytes().iter().enumerate() {
                    out[i + k] ^= m;
                }
            }
            2 if !out.is_empty() => out.truncate(self.rng.random_range(0..out.len())),
            3 => {
                let extra = self.rng.random_range(1..17);
                out.extend((0..extra).map(|_| self.rng.random::<u8>()));
            }
            4 => out.clear(),
            _ => {
                let n = self.rng.random_range(0..300);
                out = (0..n).map(|_| self.rng.random::<u8>()).collect();
            }
        }
        out
    }

    /// A serialized state whose payload has flipped bits and whose checksum
    /// was recomputed: well-formed bytes with garbage values.
    pub(super) fn forge(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = bytes.to_vec();
        let payload = STATE_HEADER_LEN..out.len() - STATE_CRC_LEN;
        for _ in 0..self.rng.random_range(1..=8) {
            let i = self.rng.random_range(payload.clone());
            out[i] ^= 1 << self.rng.random_range(0..8);
        }
        let crc = crc32fast::hash(&out[..payload.end]);
        out[payload.end..].copy_from_slice(&crc.to_le_bytes());
        out
    }
}
