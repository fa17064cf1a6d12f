//! What a run and a sweep write into their output directory: [`summary`] (`summary.json`
//! and the table printed at the end), [`timeseries`] (`timeseries.csv`), [`tracks`]
//! (`tracks.csv`), [`curves`] (`metrics.png`) and [`maps`] (`map.png`, `sets.png`).

pub mod curves;
pub mod maps;
pub mod resources;
pub mod summary;
pub mod timeseries;
pub mod tracks;
