//! Guidance variants: named sets of scenario settings (docs/design.md §4, §7).
//!
//! A variant is nothing but scenario overrides, applied after the scenario file and before the
//! user's `--set` overrides (so a user can still change any key of a variant). `fleet run
//! --variant NAME` (default `paper`) runs one; `fleet sweep --variants a,b` compares several.
//! Every variant runs the same scenario, sensors and dynamics; only `[guidance]` keys and the
//! guidance period differ.
//!
//! | variant | what it is |
//! |---|---|
//! | `paper` | the paper's MPC as written: the map and previously occluded ground (`kappa = 1`); the built-in defaults, so `fleet run` with no variant is the paper's scenario. Where the paper's text can be read two ways, or the code departed from it, the literal reading: the sets predicted and `Φ_X`, `Φ_d` measured on the estimator's cells, `Φ_d` from the UAV's ground position, `Φ_h` counting the predicted sets at the horizon's end inside recently hidden ground at the estimator's resolution, the window of eq. (28) in frames, the predicted views at the end of each period (eqs. 29-30), plans kept inside the RoI |
//! | `kappa0` | the paper's MPC, previously occluded ground not rewarded (`kappa = 0`) |
//! | `nomap` | the paper's MPC without the map (the paper's reference \[3\], `kappa = 0`) |
//! | `setfleet` | the project's planner (`guidance.planner = "setfleet"`, `uav_agent::guidance::setfleet`): a decision every 1 s, a beam search 6 s ahead valuing the sets by their area (`guidance.growth_horizon_s = 0`), targets weighted, UAVs spread and, with a finite radio range, kept within it of each other, a car whose set outgrew 10 s of travel revisited by the UAV whose lane holds it (`guidance.track_revisit_s = 10`), its weights those of the default scenario scaled to the scenario's camera footprint and cars' speed (`guidance.adapt_weights = true`, `uav_agent::guidance::weights`); it keeps the readings it was tuned with (recently hidden ground over whole guidance periods, plans inside the RoI; `predicted_views`, `hidden_resolution`, `set_resolution`, `distance_from` and `hidden_sets` are the paper's MPC's only) |

use clap::ValueEnum;
use serde::Serialize;

/// A guidance variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// The paper's MPC as written (map, occluded ground rewarded, kappa = 1): the defaults.
    Paper,
    /// The paper's MPC with the map, occluded ground not rewarded (kappa = 0).
    Kappa0,
    /// The paper's MPC without the map (reference 3 of the paper, kappa = 0).
    Nomap,
    /// The project's planner: decides every 1 s, beam search 6 s ahead, values the future
    /// growth of unobserved sets and the targets' sets, spreads the UAVs, revisits cars whose
    /// sets outgrew 10 s of travel, with weights scaled to the scenario.
    Setfleet,
}

impl Variant {
    /// Every variant, in the sweep's default column order.
    pub const ALL: [Variant; 4] = [
        Variant::Nomap,
        Variant::Kappa0,
        Variant::Paper,
        Variant::Setfleet,
    ];

    /// The variant's name, as the command line writes it.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Paper => "paper",
            Variant::Kappa0 => "kappa0",
            Variant::Nomap => "nomap",
            Variant::Setfleet => "setfleet",
        }
    }

    /// The scenario overrides that make the variant (`KEY=VALUE`, as `--set` takes them).
    ///
    /// Each variant writes every key it depends on, so that changing a built-in default never
    /// changes a variant silently.
    pub fn overrides(self) -> &'static [&'static str] {
        match self {
            Variant::Paper => &[
                "guidance.planner=paper",
                "guidance.kappa=1",
                "guidance.use_map=true",
                "guidance.hidden_resolution=estimator",
                "guidance.hidden_window=frames",
                "guidance.predicted_views=period_end",
                "guidance.border=region",
                "guidance.set_resolution=estimator",
                "guidance.distance_from=uav",
                "guidance.hidden_sets=predicted",
            ],
            Variant::Kappa0 => &[
                "guidance.planner=paper",
                "guidance.kappa=0",
                "guidance.use_map=true",
                "guidance.hidden_resolution=estimator",
                "guidance.hidden_window=frames",
                "guidance.predicted_views=period_end",
                "guidance.border=region",
                "guidance.set_resolution=estimator",
                "guidance.distance_from=uav",
                "guidance.hidden_sets=predicted",
            ],
            Variant::Nomap => &[
                "guidance.planner=paper",
                "guidance.kappa=0",
                "guidance.use_map=false",
                "guidance.hidden_resolution=estimator",
                "guidance.hidden_window=frames",
                "guidance.predicted_views=period_end",
                "guidance.border=region",
                "guidance.set_resolution=estimator",
                "guidance.distance_from=uav",
                "guidance.hidden_sets=predicted",
            ],
            Variant::Setfleet => &[
                "guidance.planner=setfleet",
                "timing.guidance_period_s=1.0",
                "guidance.use_map=true",
                "guidance.kappa=1",
                "guidance.lambda=10",
                "guidance.lookahead_periods=6",
                "guidance.beam_width=4",
                "guidance.target_weight=1",
                "guidance.growth_horizon_s=0",
                "guidance.spread_m=60",
                "guidance.track_revisit_s=10",
                "guidance.adapt_weights=true",
                "guidance.hidden_window=periods",
                "guidance.border=region",
            ],
        }
    }

    /// The overrides of the variant followed by the user's: the user's win.
    pub fn with_user_overrides(self, user: &[String]) -> Vec<String> {
        self.overrides()
            .iter()
            .map(|s| (*s).to_owned())
            .chain(user.iter().cloned())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{Planner, Scenario};

    #[test]
    fn names_parse_back_to_their_variant() {
        for v in Variant::ALL {
            assert_eq!(Variant::from_str(v.name(), false), Ok(v));
        }
        assert!(Variant::from_str("best", false).is_err());
    }

    #[test]
    fn every_variant_is_a_valid_scenario_and_paper_is_the_default() {
        for v in Variant::ALL {
            let s = Scenario::load(None, &v.with_user_overrides(&[]));
            assert!(s.is_ok(), "{}: {s:?}", v.name());
        }
        let paper = Scenario::load(None, &Variant::Paper.with_user_overrides(&[])).unwrap();
        assert_eq!(paper, Scenario::default());
        let sf = Scenario::load(None, &Variant::Setfleet.with_user_overrides(&[])).unwrap();
        assert_eq!(sf.guidance.planner, Planner::Setfleet);
        assert_eq!(sf.timing.guidance_period_s, 1.0);
        // The user's overrides come after the variant's.
        let user = ["guidance.beam_width=2".to_owned()];
        let sf = Scenario::load(None, &Variant::Setfleet.with_user_overrides(&user)).unwrap();
        assert_eq!(sf.guidance.setfleet.beam_width, 2);
    }
}
