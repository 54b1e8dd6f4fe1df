//! The grin scene description: a TOML file (camera, objects, medium, lights, render
//! settings) parsed with serde and validated, with errors that name the file, the
//! line/column and the key. The contract: docs/architecture.md (the grin-scene row and
//! "Inputs grin refuses, and where").

mod ambient;
mod de;
mod error;
pub mod frames;
mod load;
pub mod optics;
mod span;
#[cfg(test)]
mod tests;
mod types;
mod validate;

pub use ambient::AmbientIndex;
pub use error::SceneError;
pub use load::{load_scene, locate_key, parse_scene};
pub use optics::{
    AccuracyUnit, DEFAULT_OUTPUT_ACCURACY, Dots, Fringes, Knife, OpticsMode, OpticsSpec, PlaneSpec,
    Screen,
};
pub use types::*;
pub use validate::{
    MAX_IMAGE_SIDE, MAX_INDEX, MAX_NOISE_OCTAVES, MAX_OBJECTS, MAX_PILOT_RAYS, MAX_STEPS,
    MAX_WORLD_COORDINATE, MIN_WORLD_SIZE,
};
