//! Logging through the importer's `fmi2CallbackLogger`.
//!
//! Messages are formatted into a fixed stack buffer (no allocation, so models may
//! log from `fmi2DoStep`), `%` is doubled because importers pass the message to a
//! printf-style formatter, `#` because they expand `#r12#` into a variable's name
//! (FMI 2.0.4 §2.1.5), and every message names the FMI function it comes from.
//! Errors and fatal errors always reach the importer; every other category obeys
//! `fmi2SetDebugLogging`.

use std::ffi::{CStr, CString, c_char};
use std::fmt::{self, Write};

use fmi_sys::fmi2 as sys;

use crate::status::Status;

/// The log categories declared in modelDescription's `<LogCategories>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LogCategory {
    Events,
    StatusWarning,
    StatusDiscard,
    StatusError,
    StatusFatal,
    FmiCalls,
}

impl LogCategory {
    pub const ALL: [LogCategory; 6] = [
        LogCategory::Events,
        LogCategory::StatusWarning,
        LogCategory::StatusDiscard,
        LogCategory::StatusError,
        LogCategory::StatusFatal,
        LogCategory::FmiCalls,
    ];

    /// Name of the pseudo-category that switches all of them.
    pub const ALL_NAME: &'static str = "logAll";

    pub fn name(self) -> &'static CStr {
        match self {
            LogCategory::Events => c"logEvents",
            LogCategory::StatusWarning => c"logStatusWarning",
            LogCategory::StatusDiscard => c"logStatusDiscard",
            LogCategory::StatusError => c"logStatusError",
            LogCategory::StatusFatal => c"logStatusFatal",
            LogCategory::FmiCalls => c"logFmiCalls",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            LogCategory::Events => "State changes of the instance and notable model events",
            LogCategory::StatusWarning => {
                "Warnings: the call succeeded but something is not as it should be"
            }
            LogCategory::StatusDiscard => "A call whose result was discarded",
            LogCategory::StatusError => {
                "Errors: the call failed and the instance is in its error state"
            }
            LogCategory::StatusFatal => "Fatal errors",
            LogCategory::FmiCalls => "Every FMI function call with its arguments (verbose)",
        }
    }

    fn bit(self) -> u8 {
        1 << (self as u8)
    }

    pub fn from_name(name: &str) -> Option<LogCategory> {
        LogCategory::ALL
            .into_iter()
            .find(|c| c.name().to_bytes() == name.as_bytes())
    }
}

/// The importer's logger and which categories it asked for.
pub struct Logger {
    callback: sys::fmi2CallbackLogger,
    environment: sys::fmi2ComponentEnvironment,
    instance_name: CString,
    enabled: u8,
}

const ALL_BITS: u8 = 0b11_1111;
/// With `loggingOn = fmi2False` the importer still hears about warnings and
/// errors; debug categories stay quiet until it asks for them.
const DEFAULT_BITS: u8 = (1 << LogCategory::StatusWarning as u8)
    | (1 << LogCategory::StatusDiscard as u8)
    | (1 << LogCategory::StatusError as u8)
    | (1 << LogCategory::StatusFatal as u8);

impl Logger {
    pub(crate) fn new(
        callback: sys::fmi2CallbackLogger,
        environment: sys::fmi2ComponentEnvironment,
        instance_name: CString,
        logging_on: bool,
    ) -> Logger {
        Logger {
            callback,
            environment,
            instance_name,
            enabled: if logging_on { ALL_BITS } else { DEFAULT_BITS },
        }
    }

    pub fn instance_name(&self) -> &CStr {
        &self.instance_name
    }

    pub fn is_enabled(&self, category: LogCategory) -> bool {
        self.enabled & category.bit() != 0
    }

    pub(crate) fn set_all(&mut self, on: bool) {
        self.enabled = if on { ALL_BITS } else { 0 };
    }

    pub(crate) fn set(&mut self, category: LogCategory, on: bool) {
        if on {
            self.enabled |= category.bit();
        } else {
            self.enabled &= !category.bit();
        }
    }

    /// Logs `function: message`. Errors and fatal errors are always delivered.
    pub fn log_in(
        &self,
        function: &str,
        status: Status,
        category: LogCategory,
        args: fmt::Arguments<'_>,
    ) {
        let always = matches!(status, Status::Error | Status::Fatal);
        if !always && !self.is_enabled(category) {
            return;
        }
        let Some(callback) = self.callback else {
            return;
        };
        let mut message = StackMessage::new();
        let _ = write!(message, "{function}: ");
        let _ = message.write_fmt(args);
        // SAFETY: the importer gave this callback and environment to
        // fmi2Instantiate for exactly this use; all strings are NUL-terminated and
        // live for the duration of the call.
        unsafe {
            callback(
                self.environment,
                self.instance_name.as_ptr(),
                status.to_raw(),
                category.name().as_ptr(),
                message.as_c_ptr(),
            );
        }
    }

    /// An error, in the status-error category.
    pub fn error(&self, function: &str, args: fmt::Arguments<'_>) {
        self.log_in(function, Status::Error, LogCategory::StatusError, args);
    }

    pub fn warning(&self, function: &str, args: fmt::Arguments<'_>) {
        self.log_in(function, Status::Warning, LogCategory::StatusWarning, args);
    }
}

/// Capacity of a log message, including the terminating NUL.
const MESSAGE_CAPACITY: usize = 1024;
const ELLIPSIS: &str = "...";

/// A NUL-terminated message built on the stack, with `%` doubled.
struct StackMessage {
    buffer: [u8; MESSAGE_CAPACITY],
    len: usize,
    truncated: bool,
}

impl StackMessage {
    fn new() -> StackMessage {
        StackMessage {
            buffer: [0; MESSAGE_CAPACITY],
            len: 0,
            truncated: false,
        }
    }

    fn as_c_ptr(&mut self) -> *const c_char {
        self.buffer[self.len] = 0;
        self.buffer.as_ptr().cast()
    }

    /// Room for text: the ellipsis and the NUL are always kept free.
    fn room(&self) -> usize {
        MESSAGE_CAPACITY - 1 - ELLIPSIS.len() - self.len
    }

    fn push(&mut self, bytes: &[u8]) {
        self.buffer[self.len..self.len + bytes.len()].copy_from_slice(bytes);
        self.len += bytes.len();
    }
}

impl Write for StackMessage {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        if self.truncated {
            return Ok(());
        }
        for ch in s.chars() {
            let mut utf8 = [0u8; 4];
            let encoded: &[u8] = match ch {
                '%' => b"%%",
                // '#' opens a variable reference (#r12#) for the importer
                // to expand (FMI 2.0.4 §2.1.5): a literal one is written ##.
                '#' => b"##",
                // An interior NUL would cut the message short.
                '\0' => b"?",
                _ => ch.encode_utf8(&mut utf8).as_bytes(),
            };
            if encoded.len() > self.room() {
                self.truncated = true;
                self.push(ELLIPSIS.as_bytes());
                return Ok(());
            }
            self.push(encoded);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn render(args: fmt::Arguments<'_>) -> String {
        let mut m = StackMessage::new();
        m.write_fmt(args).unwrap();
        let ptr = m.as_c_ptr();
        // SAFETY: `as_c_ptr` points to the message's NUL-terminated buffer,
        // which `m` keeps alive until after the copy.
        unsafe { CStr::from_ptr(ptr) }.to_str().unwrap().to_owned()
    }

    #[test]
    fn percent_is_doubled_for_printf_importers() {
        assert_eq!(
            render(format_args!("duty 50% of {}", "100%")),
            "duty 50%% of 100%%"
        );
    }

    #[test]
    fn hash_is_doubled_so_importers_expand_no_variable_reference() {
        assert_eq!(
            render(format_args!("unknown category {:?}", "bogus#r1#")),
            "unknown category \"bogus##r1##\""
        );
    }

    #[test]
    fn interior_nul_does_not_cut_the_message() {
        assert_eq!(render(format_args!("a{}b", '\0')), "a?b");
    }

    #[test]
    fn long_messages_are_truncated_on_a_character_boundary() {
        let long = "µ".repeat(2000);
        let out = render(format_args!("{long}"));
        assert!(out.ends_with(ELLIPSIS));
        assert!(out.len() < MESSAGE_CAPACITY);
        assert!(out.trim_end_matches(ELLIPSIS).chars().all(|c| c == 'µ'));
    }

    #[test]
    fn category_names_round_trip() {
        for c in LogCategory::ALL {
            assert_eq!(LogCategory::from_name(c.name().to_str().unwrap()), Some(c));
        }
        assert_eq!(LogCategory::from_name("logNothing"), None);
    }
}
