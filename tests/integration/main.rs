//! setfleet's integration tests: one test binary, one module per topic. They spawn the real
//! binaries (built on demand by the harness in `tests/src/lib.rs`).

mod agents;
mod bench;
mod chaos;
mod city;
mod cli;
mod design_graph;
mod docs_manifest;
mod frames;
mod hosts;
mod planner;
mod radio;
mod recovery;
mod render;
mod resources;
mod run;
mod scale;
mod sweep;
mod viewer;
