//! What one UAV's planner looks at, gathered from its estimator.

use estimator::Estimator;
use protocol::flight::UavState;
use protocol::wire::PlannedView;
use sets::raster::CellSet;
use uav_agent::guidance::{ObstacleCell, PlanningInput};

use crate::FleetStepError;

/// What the planner of one UAV looks at, gathered from its estimator as the agent gathers it
/// (`uav_agent::agent`, when it takes its turn): its pose, `X̄` and every `X_j` and `H̄`
/// (borrowed from the estimator), the ground hidden recently and the obstacle cells of its map.
pub struct PlanningState<'a> {
    state: UavState,
    sets: Vec<&'a CellSet>,
    hidden: CellSet,
    unseen: &'a CellSet,
    obstacles: Vec<ObstacleCell>,
}

impl<'a> PlanningState<'a> {
    /// Gathers the inputs of UAV `uav` from its estimator, which must have folded a frame.
    pub fn of(uav: usize, estimator: &'a Estimator) -> Result<PlanningState<'a>, FleetStepError> {
        let st = estimator.state();
        let pose = st
            .pose
            .ok_or(FleetStepError::NoPose { uav, step: st.step })?;
        Ok(PlanningState {
            state: UavState {
                position: pose.position,
                yaw: pose.yaw,
            },
            sets: st.target_sets().collect(),
            hidden: st.hidden_history.recently_hidden(),
            unseen: st.hidden_history.unseen(),
            obstacles: ObstacleCell::known(&st.oem),
        })
    }

    /// The planning input of UAV `uav` with the token's plans `others` and the round's
    /// `fleet`.
    pub fn input<'b>(
        &'b self,
        uav: u32,
        others: &'b [PlannedView],
        fleet: &'b [u32],
    ) -> PlanningInput<'b> {
        PlanningInput {
            uav,
            state: self.state,
            sets: &self.sets,
            recently_hidden: &self.hidden,
            unseen: self.unseen,
            obstacles: &self.obstacles,
            others,
            fleet,
        }
    }

    /// Obstacle cells known to the map.
    pub fn obstacle_count(&self) -> usize {
        self.obstacles.len()
    }
}
