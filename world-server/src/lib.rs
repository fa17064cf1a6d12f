//! # world-server
//!
//! The scene and the ground truth of a setfleet run: a procedural city, cars on its roads,
//! the UAVs' dynamics, and the rendering of every UAV's camera frame (depth, labels, boxes)
//! by ray casts with parry3d's arithmetic, published in place into iceoryx2 shared memory.
//!
//! - [`scene`]: the city, a road grid with a ring road and prism buildings in its blocks.
//! - [`traffic`]: the cars, driving on the lanes and keeping their safety distances.
//! - [`airspace`]: the UAVs in the air, flying [`protocol::flight::advance`] behind a geofence.
//! - [`render`]: the CVS frame of a camera, with the paper's assumptions built in.
//! - [`world`]: the [`World`] that holds them and steps them together; [`WorldBuildError`]
//!   ([`error`]) is why one could not be built.
//! - [`server`]: the process loop that publishes frames and truth over iceoryx2 and collects
//!   the agents' commands, in lockstep or in real time.
//!
//! ```
//! use protocol::frame::CvsFrame;
//! use protocol::scenario::Scenario;
//! use world_server::World;
//!
//! let mut scenario = Scenario::default();
//! scenario.camera.rows = 48;
//! scenario.camera.cols = 64;
//! let mut world = World::new(&scenario)?;
//! let mut frame = CvsFrame::new_boxed();
//! world.set_yaw_ref(0, 0.3);
//! world.advance();
//! world.render(0, 7, &mut frame);
//! assert_eq!(frame.header.step, 1);
//! # Ok::<(), world_server::WorldBuildError>(())
//! ```

pub mod airspace;
pub mod error;
pub mod render;
pub mod scene;
pub mod server;
pub mod traffic;
pub mod world;

pub use error::WorldBuildError;
pub use world::World;
