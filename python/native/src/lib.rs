//! `setfleet._native`: the in-process backend of the setfleet package's environments.
//!
//! A thin layer over the `episode` crate: `Episode` is one run of the fleet in this process
//! whose learning UAVs ask the caller for their decisions with the request bytes an agent
//! sends, and `run_many` steps several at once over threads. The GIL is released while
//! the fleet steps.

use std::path::PathBuf;

use episode::{EpisodeError, EpisodeSpec, Episodes};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

/// An error of the episode as a Python exception: what the caller asked is a `ValueError`,
/// a failure of the run a `RuntimeError`.
fn py_err(e: EpisodeError) -> PyErr {
    match e {
        EpisodeError::Variant(_)
        | EpisodeError::Scenario(_)
        | EpisodeError::NotAsked(_)
        | EpisodeError::Unanswered(_) => PyValueError::new_err(e.to_string()),
        _ => PyRuntimeError::new_err(e.to_string()),
    }
}

/// One run of the fleet in this process (`episode::Episode`).
#[pyclass(module = "setfleet._native")]
struct Episode {
    /// Taken out while [`run_many`] steps it on another thread.
    inner: Option<Box<episode::Episode>>,
}

impl Episode {
    fn get(&self) -> PyResult<&episode::Episode> {
        self.inner
            .as_deref()
            .ok_or_else(|| PyRuntimeError::new_err("the episode is being stepped"))
    }

    fn get_mut(&mut self) -> PyResult<&mut episode::Episode> {
        self.inner
            .as_deref_mut()
            .ok_or_else(|| PyRuntimeError::new_err("the episode is being stepped"))
    }
}

#[pymethods]
impl Episode {
    /// The run `fleet run` would make of these flags (`--scenario`, `--variant`, `--set`,
    /// `--seed`, `--duration`, `--uavs`, `--planner external:<learners>`).
    #[new]
    #[allow(clippy::too_many_arguments)] // the flags of `fleet run`, as keyword arguments
    #[pyo3(signature = (scenario, variant, overrides, seed, duration, uavs, learners))]
    fn new(
        py: Python<'_>,
        scenario: Option<PathBuf>,
        variant: String,
        overrides: Vec<String>,
        seed: u64,
        duration: Option<f64>,
        uavs: Option<u32>,
        learners: Vec<u32>,
    ) -> PyResult<Self> {
        let spec = EpisodeSpec {
            scenario,
            variant,
            overrides,
            seed,
            duration_s: duration,
            uavs,
            learners,
        };
        let inner = py.detach(|| episode::Episode::new(&spec)).map_err(py_err)?;
        Ok(Episode {
            inner: Some(Box::new(inner)),
        })
    }

    /// Steps until a learner asks (`True`) or the run ended (`False`).
    fn run(&mut self, py: Python<'_>) -> PyResult<bool> {
        let inner = self.get_mut()?;
        py.detach(|| inner.run()).map_err(py_err)
    }

    /// The pending requests: `(uav, step, request bytes)` in token order.
    fn pending<'py>(&self, py: Python<'py>) -> PyResult<Vec<(u32, u64, Bound<'py, PyBytes>)>> {
        Ok(self
            .get()?
            .pending()
            .iter()
            .map(|p| (p.uav, p.step, PyBytes::new(py, &p.bytes)))
            .collect())
    }

    /// Answers `uav`'s pending request with an answer's bytes (refused bytes: the UAV's own
    /// planner decides, as an agent's does).
    fn answer(&mut self, uav: u32, data: &[u8]) -> PyResult<()> {
        self.get_mut()?.answer(uav, data).map_err(py_err)
    }

    /// Whether the run has taken its last step.
    #[getter]
    fn finished(&self) -> PyResult<bool> {
        Ok(self.get()?.finished())
    }

    /// The world's current step.
    #[getter]
    fn step(&self) -> PyResult<u64> {
        Ok(self.get()?.fleet().world().step())
    }

    /// Steps of the run.
    #[getter]
    fn total_steps(&self) -> PyResult<u64> {
        Ok(self.get()?.scenario().steps())
    }

    /// Guarantee violations over the steps measured so far.
    #[getter]
    fn violations(&self) -> PyResult<u64> {
        Ok(self.get()?.violations())
    }

    /// Requests made, answers taken, answers refused, and of the answers taken those that
    /// deferred to the UAV's own planner.
    #[getter]
    fn counts(&self) -> PyResult<(u64, u64, u64, u64)> {
        let c = self.get()?.counts();
        Ok((c.asked, c.answered, c.malformed, c.deferred))
    }

    /// The last measured step's mean UA over the agents (`None` before any step).
    #[getter]
    fn ua(&self) -> PyResult<Option<f64>> {
        Ok(self
            .get()?
            .series()
            .last()
            .and_then(|m| m.mean.as_ref())
            .map(|m| m.ua))
    }

    /// `timeseries.csv` of the steps measured so far.
    fn timeseries_csv(&self) -> PyResult<String> {
        Ok(self.get()?.timeseries_csv())
    }
}

/// Steps each of `episodes` until a learner asks or the run ends, at once over up to
/// `threads` threads; each one's result as [`Episode::run`] gives it.
#[pyfunction]
fn run_many(
    py: Python<'_>,
    mut episodes: Vec<PyRefMut<'_, Episode>>,
    threads: usize,
) -> PyResult<Vec<bool>> {
    if episodes.iter().any(|e| e.inner.is_none()) {
        return Err(PyRuntimeError::new_err("an episode is being stepped"));
    }
    let taken = episodes
        .iter_mut()
        .filter_map(|e| e.inner.take())
        .map(|inner| *inner)
        .collect();
    let mut vector = Episodes::new(taken, threads);
    let which: Vec<usize> = (0..vector.len()).collect();
    let results = py.detach(|| vector.run(&which));
    for (e, inner) in episodes.iter_mut().zip(vector.into_episodes()) {
        e.inner = Some(Box::new(inner));
    }
    results.into_iter().map(|r| r.map_err(py_err)).collect()
}

/// The module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Episode>()?;
    m.add_function(wrap_pyfunction!(run_many, m)?)?;
    Ok(())
}
