//! Cars driven by a recorded trace: a pose for every car at every CVS period, from a file
//! (`city.traffic = "trace"`) or from SUMO ([`crate::traffic::sumo`]).
//!
//! A trace is not trusted. Before a world drives its cars by one,
//! [`Trace::check`](crate::traffic::trace::Trace::check) holds every car's every step to
//! what the estimator assumes of a target, and refuses the trace with an error naming the car
//! and the time otherwise:
//! - a car moves at most `v_max T` from one period to the next (exactly: no tolerance);
//! - its centre stays `targets.building_clearance_m` or more from every building;
//! - it stays inside the region.
//!
//! The file format is CSV with a header, one row per car and period, in any order:
//!
//! ```text
//! time_s,car,x_m,y_m,heading_rad
//! 0,0,-12.5,40.0,1.5708
//! 0,1,30.0,-8.25,0
//! 0.5,0,-12.5,41.0,1.5708
//! ```
//!
//! Times are multiples of `timing.cvs_period_s` from 0; cars are numbered from 0, and every
//! car has a row at every period until the trace ends, which is no earlier than the run's end.
//! Positions are the ground point under the car's centre in the region's frame (metres, x
//! east, y north); headings are radians counter-clockwise from east. After its end a trace
//! holds its cars where they are.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use protocol::scenario::Scenario;
use sets::math::{Point2, Real};

use super::CarPose;
use crate::scene::City;

/// The header a trace file starts with.
pub const HEADER: &str = "time_s,car,x_m,y_m,heading_rad";
/// The largest trace file read, bytes: a day of 32 cars at 2 Hz.
pub const MAX_FILE_BYTES: u64 = 512 << 20;
/// How far a row's time may be from a multiple of the period, seconds.
const TIME_TOLERANCE_S: Real = 1e-6;

/// Why a trace cannot drive a world's cars.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The file cannot be read.
    #[error("cannot read the trace {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error("the trace {path} has {bytes} bytes, more than the {MAX_FILE_BYTES} read")]
    TooLarge {
        /// The file.
        path: String,
        /// Its size.
        bytes: u64,
    },
    /// A line is not a row of the format.
    #[error("trace line {line}: {what}")]
    Format {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// A car has no pose at some period.
    #[error("car {car} has no row at {time_s} s")]
    Missing {
        /// The car.
        car: u32,
        /// The period's time.
        time_s: Real,
    },
    /// The trace drives another number of cars than the scenario's.
    #[error("the trace drives {found} cars, targets.count is {want}")]
    Count {
        /// Cars in the trace.
        found: usize,
        /// `targets.count`.
        want: u32,
    },
    /// The trace ends before the run does.
    #[error("the trace ends at {end_s} s, before the run's end at {duration_s} s")]
    Short {
        /// The trace's last time.
        end_s: Real,
        /// `duration_s`.
        duration_s: Real,
    },
    /// A car moves farther than `v_max T` in one period.
    #[error(
        "car {car} moves {moved_m:.6} m from {from_s} s to {to_s} s, more than v_max T = \
         {max_m} m"
    )]
    Jump {
        /// The car.
        car: u32,
        /// The period's start.
        from_s: Real,
        /// The period's end.
        to_s: Real,
        /// How far it moved.
        moved_m: Real,
        /// `v_max T`.
        max_m: Real,
    },
    /// A car comes closer to a building than the clearance.
    #[error(
        "car {car} at {time_s} s is {distance_m:.3} m from building {building}, closer than \
         targets.building_clearance_m = {need_m} m"
    )]
    Clearance {
        /// The car.
        car: u32,
        /// When.
        time_s: Real,
        /// The building's index in the scene.
        building: usize,
        /// The distance from the car's centre to the building's footprint.
        distance_m: Real,
        /// `targets.building_clearance_m`.
        need_m: Real,
    },
    /// A car leaves the region.
    #[error("car {car} at {time_s} s is at ({x:.3}, {y:.3}), outside the region")]
    Outside {
        /// The car.
        car: u32,
        /// When.
        time_s: Real,
        /// Where, x.
        x: Real,
        /// Where, y.
        y: Real,
    },
}

/// Every car's pose at every period of a drive, period 0 at time 0 (`poses[k][car]`, the car
/// id its index; speeds are the distance from the period before, divided by the period).
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    period_s: Real,
    poses: Vec<Vec<CarPose>>,
}

impl Trace {
    /// The trace of `points[k][car] = (x, y, heading)` at periods of `period_s`.
    pub fn from_points(period_s: Real, points: &[Vec<(Real, Real, Real)>]) -> Trace {
        let mut poses: Vec<Vec<CarPose>> = Vec::with_capacity(points.len());
        for step in points {
            let prev = poses.last();
            let row = (step.iter().enumerate())
                .map(|(car, &(x, y, heading))| {
                    let position = Point2::new(x, y);
                    let moved =
                        prev.map_or(0.0, |p: &Vec<CarPose>| (position - p[car].position).norm());
                    CarPose {
                        id: car as u32,
                        position,
                        heading,
                        speed_mps: moved / period_s,
                    }
                })
                .collect();
            poses.push(row);
        }
        Trace { period_s, poses }
    }

    /// Reads a trace file of periods `period_s` (the format above).
    pub fn read(path: &Path, period_s: Real) -> Result<Trace, TraceError> {
        let shown = path.display().to_string();
        let read_error = |source| TraceError::Read {
            path: shown.clone(),
            source,
        };
        let bytes = std::fs::metadata(path).map_err(read_error)?.len();
        if bytes > MAX_FILE_BYTES {
            return Err(TraceError::TooLarge { path: shown, bytes });
        }
        let text = std::fs::read_to_string(path).map_err(read_error)?;
        Trace::parse(&text, period_s)
    }

    /// Parses a trace's text (the format above).
    pub fn parse(text: &str, period_s: Real) -> Result<Trace, TraceError> {
        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
        match lines.next() {
            Some((_, header)) if header == HEADER => {}
            _ => {
                return Err(TraceError::Format {
                    line: 1,
                    what: format!("the header must be `{HEADER}`"),
                });
            }
        }
        let mut rows: BTreeMap<(usize, u32), (Real, Real, Real)> = BTreeMap::new();
        let (mut steps, mut cars) = (0usize, 0u32);
        for (line, row) in lines.filter(|(_, l)| !l.is_empty()) {
            let format = |what: String| TraceError::Format { line, what };
            let fields: Vec<&str> = row.split(',').map(str::trim).collect();
            let [time, car, x, y, heading] = fields[..] else {
                return Err(format(format!("{} fields, not 5", fields.len())));
            };
            let number = |name: &str, text: &str| -> Result<Real, TraceError> {
                match text.parse::<Real>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(format(format!("{name} {text:?} is not a finite number"))),
                }
            };
            let time = number("time_s", time)?;
            let k = (time / period_s).round();
            if time < 0.0 || (time - k * period_s).abs() > TIME_TOLERANCE_S || k > 1e8 {
                return Err(format(format!(
                    "time {time} s is not a multiple of the period {period_s} s from 0"
                )));
            }
            let car: u32 = (car.parse().ok())
                .filter(|&c| c < 1 << 16)
                .ok_or_else(|| format(format!("car {car:?} is not a car number")))?;
            let pose = (
                number("x_m", x)?,
                number("y_m", y)?,
                number("heading_rad", heading)?,
            );
            let k = k as usize;
            if rows.insert((k, car), pose).is_some() {
                return Err(format(format!("a second row for car {car} at {time} s")));
            }
            steps = steps.max(k + 1);
            cars = cars.max(car + 1);
        }
        if steps == 0 {
            return Err(TraceError::Format {
                line: 1,
                what: "no rows".into(),
            });
        }
        let mut points = Vec::with_capacity(steps);
        for k in 0..steps {
            let row = (0..cars)
                .map(|car| {
                    (rows.get(&(k, car)).copied()).ok_or(TraceError::Missing {
                        car,
                        time_s: k as Real * period_s,
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            points.push(row);
        }
        Ok(Trace::from_points(period_s, &points))
    }

    /// The trace as the file format above.
    pub fn to_csv(&self) -> String {
        let mut out = format!("{HEADER}\n");
        for (k, step) in self.poses.iter().enumerate() {
            let t = k as Real * self.period_s;
            for p in step {
                let (x, y, h) = (p.position.x, p.position.y, p.heading);
                out.push_str(&format!("{t},{},{x},{y},{h}\n", p.id));
            }
        }
        out
    }

    /// Number of cars.
    pub fn cars(&self) -> usize {
        self.poses.first().map_or(0, Vec::len)
    }

    /// Number of periods, the first at time 0.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Whether the trace has no period.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// The cars at period `k`; after the trace's end, where they ended, standing.
    pub fn poses_at(&self, k: usize) -> Vec<CarPose> {
        match self.poses.get(k) {
            Some(step) => step.clone(),
            None => (self.poses.last().into_iter().flatten())
                .map(|p| CarPose {
                    speed_mps: 0.0,
                    ..*p
                })
                .collect(),
        }
    }

    /// Checks the trace against what the world promises of its cars (module docs): the
    /// scenario's number of cars, to the run's end, every step at most `v_max T`, every
    /// centre `targets.building_clearance_m` from `city`'s buildings and inside the region.
    pub fn check(&self, city: &City, scenario: &Scenario) -> Result<(), TraceError> {
        let t = &scenario.targets;
        if self.cars() != t.count as usize {
            return Err(TraceError::Count {
                found: self.cars(),
                want: t.count,
            });
        }
        let end_s = (self.len() - 1) as Real * self.period_s;
        if end_s + TIME_TOLERANCE_S < scenario.duration_s {
            return Err(TraceError::Short {
                end_s,
                duration_s: scenario.duration_s,
            });
        }
        let max_m = t.max_speed_mps * self.period_s;
        let need_m = t.building_clearance_m;
        let h = scenario.region.half_extent_m;
        for (k, step) in self.poses.iter().enumerate() {
            let time_s = k as Real * self.period_s;
            for p in step {
                let (car, q) = (p.id, p.position);
                if q.x.abs() > h || q.y.abs() > h {
                    return Err(TraceError::Outside {
                        car,
                        time_s,
                        x: q.x,
                        y: q.y,
                    });
                }
                if k > 0 {
                    let moved_m = (q - self.poses[k - 1][car as usize].position).norm();
                    if moved_m > max_m {
                        return Err(TraceError::Jump {
                            car,
                            from_s: time_s - self.period_s,
                            to_s: time_s,
                            moved_m,
                            max_m,
                        });
                    }
                }
                for (building, b) in city.buildings.iter().enumerate() {
                    let distance_m = b.footprint_distance(&q);
                    if distance_m < need_m {
                        return Err(TraceError::Clearance {
                            car,
                            time_s,
                            building,
                            distance_m,
                            need_m,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

/// Cars replaying a checked [`Trace`], one period per step.
#[derive(Clone, Debug)]
pub struct TraceCars {
    trace: Arc<Trace>,
    step: usize,
}

impl TraceCars {
    /// The cars of `trace`, at its start.
    pub fn new(trace: Trace) -> TraceCars {
        TraceCars {
            trace: Arc::new(trace),
            step: 0,
        }
    }

    /// Advances one period.
    pub fn step(&mut self) {
        self.step += 1;
    }

    /// Where the cars are.
    pub fn poses(&self) -> Vec<CarPose> {
        self.trace.poses_at(self.step)
    }

    /// The number of cars.
    pub fn len(&self) -> usize {
        self.trace.cars()
    }

    /// Whether there are no cars.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_cars() -> String {
        format!("{HEADER}\n0,0,0,0,0\n0,1,10,10,1\n0.5,1,10,11,1\n0.5,0,1,0,0\n")
    }

    #[test]
    fn a_trace_reads_back_what_it_writes() {
        let trace = Trace::parse(&two_cars(), 0.5).unwrap();
        assert_eq!((trace.cars(), trace.len()), (2, 2));
        let car1 = trace.poses_at(1)[1];
        assert_eq!(car1.position, Point2::new(10.0, 11.0));
        assert_eq!(car1.speed_mps, 2.0);
        assert_eq!(Trace::parse(&trace.to_csv(), 0.5).unwrap(), trace);
        // After the end: where they ended, standing.
        let after = trace.poses_at(7);
        assert_eq!(after[1].position, car1.position);
        assert_eq!(after[1].speed_mps, 0.0);
    }

    #[test]
    fn malformed_traces_are_refused_with_the_line() {
        let cases = [
            ("time,car,x,y,h\n", "header"),
            (&*format!("{HEADER}\n0,0,0,0\n"), "line 2: 4 fields"),
            (&*format!("{HEADER}\n0,0,0,nan,0\n"), "line 2: y_m"),
            (&*format!("{HEADER}\n0.3,0,0,0,0\n"), "line 2: time 0.3"),
            (&*format!("{HEADER}\n0,-1,0,0,0\n"), "line 2: car"),
            (
                &*format!("{HEADER}\n0,0,0,0,0\n0,0,1,0,0\n"),
                "line 3: a second row",
            ),
            (
                &*format!("{HEADER}\n0,0,0,0,0\n0,1,5,5,0\n0.5,0,1,0,0\n"),
                "car 1 has no row",
            ),
            (&*format!("{HEADER}\n"), "no rows"),
        ];
        for (text, want) in cases {
            let e = Trace::parse(text, 0.5).unwrap_err().to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }
}
