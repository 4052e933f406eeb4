//! The subcommands of `piezo-identify` and what they share; the library does
//! the math, these modules parse, load, print and write.

pub(crate) mod arguments;
pub(crate) mod bouc_wen;
pub(crate) mod compare;
pub(crate) mod inverse_pi;
pub(crate) mod progress;
pub(crate) mod records;
pub(crate) mod report;
pub(crate) mod stage;
