//! A co-simulation master for FMI 2.0 co-simulation FMUs.
//!
//! The scenario of a run is data ([`scenario`]): the FMUs and their parameter
//! values by FMI name (parameter sets such as `dist/presets/*.json`), the
//! connections, the trajectories that drive inputs ([`trajectory`]) and how
//! the run is measured ([`metrics`]). [`master::run`] loads the FMUs through
//! the importer (`fmi2-import`), couples them with demo/cosim.py's algorithm
//! (fixed step, Jacobi, references previewed) and returns the metrics and,
//! on request, the time series ([`series`]).
//!
//! The `piezo-cosim` command runs a scenario file; the sweeps of the Python
//! package (`python -m demo sweep`) run it on dask workers.

pub mod master;
pub mod metrics;
pub mod scenario;
pub mod series;
pub mod trajectory;

pub use master::{OpenFmus, RunError, RunOptions, RunOutput, Series, run, run_with};
pub use scenario::Scenario;
