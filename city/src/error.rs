//! The crate's errors: one enum per fallible operation.

use std::path::PathBuf;

/// Why a scene file could not be read ([`crate::scene::CityScene::read`]).
#[derive(Debug, thiserror::Error)]
pub enum SceneReadError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
    /// The file is larger than [`crate::scene::MAX_SCENE_BYTES`].
    #[error(
        "{path}: {bytes} bytes, more than a scene may have ({} bytes)",
        crate::scene::MAX_SCENE_BYTES
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// The file is not a scene in JSON.
    #[error("{path}: not a city scene: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        reason: String,
    },
    /// The scene breaks what the world relies on.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Why a city could not be imported ([`crate::import::import`]).
#[derive(Debug, thiserror::Error)]
pub enum CityImportError {
    /// The OpenStreetMap file could not be read as PBF.
    #[error("{path}: not a readable OpenStreetMap PBF file: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        reason: String,
    },
    /// An option is out of its range.
    #[error("{option} = {value}: {expected}")]
    Option {
        /// The option, as the command line spells it.
        option: &'static str,
        /// Its value.
        value: String,
        /// The accepted range.
        expected: &'static str,
    },
    /// The centre is not inside the file's data.
    #[error(
        "the centre {lat:.6},{lon:.6} lies outside the file's data \
         (latitudes {south:.6} to {north:.6}, longitudes {west:.6} to {east:.6})"
    )]
    CentreOutside {
        /// Latitude asked.
        lat: f64,
        /// Longitude asked.
        lon: f64,
        /// The data's southern edge.
        south: f64,
        /// The data's western edge.
        west: f64,
        /// The data's northern edge.
        north: f64,
        /// The data's eastern edge.
        east: f64,
    },
    /// The file has no nodes at all.
    #[error("the file holds no nodes")]
    Empty,
    /// No road cars may use is left inside the square.
    #[error(
        "no drivable road is left in the square: {mapped_m:.0} m of drivable road mapped, \
         {cut_m:.0} m of it cut ({reasons})"
    )]
    NoDrivableRoad {
        /// Metres of drivable road inside the square before cutting.
        mapped_m: f64,
        /// Metres cut.
        cut_m: f64,
        /// The cuts by reason.
        reasons: String,
    },
}
