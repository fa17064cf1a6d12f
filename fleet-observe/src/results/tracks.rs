//! `tracks.csv`: every UAV's true camera pose at every step the observer processed, one row
//! per UAV and step (`step,time_s,uav,x,y,z,yaw`; metres and radians). No wall-clock column, so
//! the file is reproducible in lockstep: where a planner sent a UAV shows here.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;

/// One UAV's true pose at one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UavPose {
    /// The step.
    pub step: u64,
    /// Its simulated time, s.
    pub time_s: f64,
    /// The UAV.
    pub uav: u32,
    /// The camera's optical centre, m.
    pub position: [f64; 3],
    /// Its yaw, rad.
    pub yaw: f64,
}

/// The header row.
pub const HEADER: &str = "step,time_s,uav,x,y,z,yaw";

/// The CSV text of `poses`.
pub fn to_csv(poses: &[UavPose]) -> String {
    let mut out = String::with_capacity(64 * (poses.len() + 1));
    out.push_str(HEADER);
    out.push('\n');
    for p in poses {
        let [x, y, z] = p.position;
        // Writing into a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{x},{y},{z},{}",
            p.step, p.time_s, p.uav, p.yaw
        );
    }
    out
}

/// Writes `tracks.csv` to `path`.
pub fn write(poses: &[UavPose], path: &Path) -> anyhow::Result<()> {
    std::fs::write(path, to_csv(poses)).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_row_per_pose_under_the_header() {
        let p = UavPose {
            step: 3,
            time_s: 1.5,
            uav: 1,
            position: [1.0, -2.5, 60.0],
            yaw: 0.25,
        };
        assert_eq!(to_csv(&[p]), format!("{HEADER}\n3,1.5,1,1,-2.5,60,0.25\n"));
    }
}
