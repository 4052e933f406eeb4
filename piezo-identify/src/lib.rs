//! Identification of seed 000's modified inverse Prandtl-Ishlinskii model (and
//! its traditional and classical rivals) and of seed 001's asymmetric Bouc-Wen
//! model from voltage/displacement data.
//!
//! - [`data`]: reads a numeric record (columns by index or header name, time
//!   column or sample rate) and refuses malformed files with `file:line:
//!   problem`.
//! - [`fit`]: separable least squares for seed 000 §3.1, F = ‖u_model − u‖²
//!   (eq. 7). For fixed (c, w_s) the models are linear in their weights,
//!   solved exactly ([`least_squares`]: column-scaled Householder QR + SVD of
//!   R); Nelder-Mead (argmin) searches (c, w_s) from random starts in parallel
//!   (rayon), deterministic for a seed. [`fit::fit_modified_inverse_pi`]
//!   returns a [`piezo_models::InversePiParams`].
//! - [`models`]: the traditional inverse P-I rivals (10 backlash + 6 or 10
//!   dead-zone operators, rate-dependent weights, no cubic) and the classical
//!   P-I model, streaming and allocation-free like
//!   [`piezo_models::ModifiedInversePi`].
//! - [`regressors`]: the linear regressors of each model for given nonlinear
//!   parameters.
//! - [`compare`]: seed 000's model comparison (F of the three inverse models,
//!   evaluation time per sample, Fig. 4) on data from eq. (6) driving the
//!   simulated stage.
//! - [`validation`]: sensor offset, and voltage errors as % of the input span
//!   and as equivalent displacement.
//! - [`plant`]: drives a plant FMU through its FMI 2.0 C ABI (open-loop
//!   eq. (6) records, closed loop with the controller law).
//! - [`decoupling`]: fits seed 000's compensations D_i (eq. 11, Table 2) to
//!   single-axis coupling errors.
//! - [`fingerprints`]: the plant's calibration fingerprints
//!   ([`piezo_models::fingerprint`]) measured through its FMU.
//! - [`stage`]: the whole procedure on a plant FMU, giving the `stage`
//!   controller preset.
//! - [`gapso`]: seed 001's GA-PSO, a bounded global minimiser (rayon,
//!   deterministic for a seed).
//! - [`bouc_wen_fit`]: seed 001's asymmetric Bouc-Wen model (eq. 3-4) fitted
//!   by GA-PSO on eq. (5), then refined by Levenberg-Marquardt.
//! - [`xy200s`]: seed 001's XY200S stage as a FlexureStage preset, converted
//!   from the printed Tables 1-2 by identification.
//!
//! The models know nothing of files; the `piezo-identify` binary does the I/O.
//! `README.md` beside this crate gives the method, every reading of the paper
//! and the measured figures.

pub mod bouc_wen_fit;
pub mod compare;
pub mod data;
pub mod decoupling;
pub mod fingerprints;
pub mod fit;
pub mod gapso;
pub mod lab_records;
pub mod least_squares;
pub mod models;
pub mod plant;
pub mod protocol;
pub mod regressors;
pub mod segments;
pub mod stage;
pub mod validation;
pub mod xy200s;

pub use data::{Column, DataError, ReadOptions, Record, Roles, Sampling, read_record};
pub use fit::{
    Fit, FitError, FitOptions, FitQuality, StartResult, fit_classical_pi, fit_modified_inverse_pi,
    fit_modified_inverse_pi_with_progress, fit_traditional_inverse_pi,
};
pub use models::{
    ClassicalPi, ClassicalPiParams, InverseHysteresis, TraditionalInversePi,
    TraditionalInversePiParams,
};
