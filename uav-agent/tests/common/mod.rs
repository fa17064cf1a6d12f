//! What the estimator tests share.

use uav_agent::estimator::message::{self, EstimateOutbox};
use uav_agent::estimator::{Estimator, EstimatorConfig, PeerEstimate};

/// Every agent's estimate as its peers receive it: composed by its outbox, encoded and
/// decoded (in the order of `estimators`, which `outboxes` follows).
pub fn exchanged(
    estimators: &mut [Estimator],
    outboxes: &mut [EstimateOutbox],
    config: &EstimatorConfig,
) -> Vec<PeerEstimate> {
    estimators
        .iter_mut()
        .zip(outboxes)
        .map(|(est, outbox)| {
            let msg = outbox.compose(est.state_mut());
            let bytes = message::to_bytes(&msg).expect("encode");
            PeerEstimate::from_bytes(&bytes, config).expect("decode")
        })
        .collect()
}
