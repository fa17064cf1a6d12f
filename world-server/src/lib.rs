//! # world-server
//!
//! The scene and the ground truth of a setfleet run: a procedural city, cars on its roads,
//! the UAVs' dynamics, and the rendering of every UAV's camera frame (depth, labels, boxes)
//! by parry3d ray casts, published in place into iceoryx2 shared memory.

#![warn(missing_docs)]

pub mod world;

pub use world::{World, WorldBuildError};
