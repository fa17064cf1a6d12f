//! Cars driven by SUMO (`city.traffic = "sumo"`): the traffic simulator of the field drives
//! an imported city's cars, ahead of the world, from the run's seed.
//!
//! **Ahead, not in lockstep.** Nothing in the world acts on the cars (the UAVs only watch), so
//! SUMO can drive the whole run before the world starts and hand over a [`Trace`](crate::traffic::trace::Trace), which the
//! world checks whole ([`Trace::check`](crate::traffic::trace::Trace::check)) and
//! replays. A lockstep link (TraCI) would add a
//! socket round trip to every step of every run and a second process to keep alive, and would
//! find a car that breaks the estimator's assumptions only when it happens, mid-run; a trace
//! is refused before any agent sees a frame. The cost is one SUMO run at the start, well
//! under a second for the shipped city.
//!
//! How a run's trace is made, in a temporary directory:
//! 1. **The network.** `netconvert` builds it from the scene's roads: a node per point, an
//!    edge per road piece and direction (one-way streets kept), one lane each, the scene's
//!    lane offset wide, so a lane's centre runs half the offset from the road's centreline and
//!    the corners SUMO rounds at junctions stay near it; junction radius 1 m.
//! 2. **Where cars can drive for good.** The largest set of edges from which every edge of the
//!    set can be reached (a strongly connected component of SUMO's connections): a car on it
//!    never meets a dead end it cannot turn out of.
//! 3. **Routes from the seed.** Each car starts on an edge drawn by length and drives a random
//!    walk over the set, long enough for the warm-up and the whole run at `v_max`.
//! 4. **The drive.** `sumo` with the period as its step, the cars' size, top speed
//!    `v_max (1 - 10^-4)` (SUMO rounds lane lengths; the margin keeps every step within
//!    `v_max T`), teleports off, its own random numbers seeded from the run's seed. The cars
//!    enter where SUMO finds room; the trace starts at the first period all of them are in
//!    (at most [`WARMUP_S`](crate::traffic::sumo::WARMUP_S)).
//!
//! A car's position is where SUMO puts its front bumper: the car drives exactly SUMO's lanes,
//! and SUMO's gaps keep the boxes apart.
//!
//! SUMO is found through `SUMO_HOME` (its `bin/`), then `PATH`; `pip install
//! eclipse-sumo==1.28.0` gives both (`SUMO_HOME` is `python -c "import sumo;
//! print(sumo.SUMO_HOME)"`).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use city::scene::{Oneway, RoadNetwork};
use protocol::scenario::Scenario;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sets::math::Real;

use super::trace::Trace;

/// The command that installs SUMO.
pub const INSTALL: &str = "pip install eclipse-sumo==1.28.0, then set SUMO_HOME to \
     `python -c \"import sumo; print(sumo.SUMO_HOME)\"` or put its `sumo` and `netconvert` \
     on PATH";
/// The longest SUMO may take to fit every car in, seconds of its time.
pub const WARMUP_S: Real = 120.0;
/// The longest a SUMO tool may run, wall time.
const TOOL_TIMEOUT: Duration = Duration::from_secs(300);
/// The gap SUMO keeps behind a standing car at least, metres (its default).
const MIN_GAP_M: Real = 2.5;
/// The share of `v_max` SUMO's cars may reach.
const TOP_SPEED_SHARE: Real = 1.0 - 1e-4;
/// Junction radius, metres: small, so that the corners stay near the lanes.
const JUNCTION_RADIUS_M: Real = 1.0;

/// Why SUMO could not drive a run's cars.
#[derive(Debug, thiserror::Error)]
pub enum SumoError {
    /// SUMO is not installed where it is looked for.
    #[error("SUMO's {tool} was not found (SUMO_HOME, PATH): {INSTALL}")]
    Missing {
        /// The tool looked for.
        tool: &'static str,
    },
    /// A file of the drive could not be written or read.
    #[error("SUMO's files ({what}): {source}")]
    Io {
        /// Which.
        what: String,
        /// Why.
        source: std::io::Error,
    },
    /// A SUMO tool failed or timed out.
    #[error("{tool} failed ({status}): {stderr}")]
    Tool {
        /// The tool.
        tool: &'static str,
        /// Its exit status, or the timeout.
        status: String,
        /// The end of what it printed.
        stderr: String,
    },
    /// SUMO wrote something this reader does not understand.
    #[error("SUMO's {file}: {what}")]
    Output {
        /// The file.
        file: &'static str,
        /// What is wrong.
        what: String,
    },
    /// The network has no road a car could drive on for good.
    #[error("the SUMO network has no loop of roads to drive on")]
    NoLoop,
    /// SUMO could not fit every car in.
    #[error(
        "SUMO fitted only {placed} of the {cars} cars in within {WARMUP_S} s: the network holds \
         fewer cars apart (lower targets.count)"
    )]
    Crowded {
        /// `targets.count`.
        cars: u32,
        /// The most cars SUMO had in at once.
        placed: usize,
    },
}

/// Where SUMO's tools are.
#[derive(Clone, Debug)]
pub struct SumoTools {
    netconvert: PathBuf,
    sumo: PathBuf,
}

impl SumoTools {
    /// Finds `netconvert` and `sumo` in `$SUMO_HOME/bin`, then on `PATH`.
    pub fn locate() -> Result<SumoTools, SumoError> {
        let home = std::env::var_os("SUMO_HOME").map(|h| PathBuf::from(h).join("bin"));
        let path = std::env::var_os("PATH").unwrap_or_default();
        let dirs: Vec<PathBuf> = home
            .into_iter()
            .chain(std::env::split_paths(&path))
            .collect();
        let find = |tool: &'static str| {
            (dirs.iter().map(|d| d.join(tool)))
                .find(|p| p.is_file())
                .ok_or(SumoError::Missing { tool })
        };
        Ok(SumoTools {
            netconvert: find("netconvert")?,
            sumo: find("sumo")?,
        })
    }

    /// The first line `sumo --version` prints, e.g. `Eclipse SUMO sumo 1.28.0` (what the run
    /// cache keys SUMO's runs by).
    pub fn version(&self) -> Result<String, SumoError> {
        let out = Command::new(&self.sumo)
            .arg("--version")
            .stdin(Stdio::null())
            .output()
            .map_err(|e| io("sumo --version", e))?;
        let text = String::from_utf8_lossy(&out.stdout);
        match text.lines().next() {
            Some(line) if out.status.success() => Ok(line.trim().to_owned()),
            _ => Err(SumoError::Tool {
                tool: "sumo",
                status: out.status.to_string(),
                stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
            }),
        }
    }

    /// SUMO's drive of `scenario`'s cars over `roads`, routes drawn from `rng` (module docs).
    pub fn drive(
        &self,
        roads: &RoadNetwork,
        scenario: &Scenario,
        rng: &mut ChaCha8Rng,
    ) -> Result<Trace, SumoError> {
        let dir = tempfile::Builder::new()
            .prefix("setfleet-sumo-")
            .tempdir()
            .map_err(|source| io("a temporary directory", source))?;
        let dir = dir.path();
        write(&dir.join("net.nod.xml"), &nodes(roads))?;
        write(&dir.join("net.edg.xml"), &edges(roads, scenario))?;
        let net_file = dir.join("net.net.xml");
        run(
            "netconvert",
            Command::new(&self.netconvert)
                .arg("--node-files")
                .arg(dir.join("net.nod.xml"))
                .arg("--edge-files")
                .arg(dir.join("net.edg.xml"))
                .arg("--output-file")
                .arg(&net_file)
                .args(["--offset.disable-normalization", "true"])
                .args(["--default.junctions.radius", &JUNCTION_RADIUS_M.to_string()])
                .args(["--precision", "6", "--no-warnings", "true"]),
            dir,
        )?;
        let net = Network::read(&read(&net_file)?)?;
        let routes = net.routes(scenario, rng)?;
        let route_file = dir.join("cars.rou.xml");
        write(&route_file, &route_xml(&routes, scenario))?;
        let fcd_file = dir.join("fcd.xml");
        let period = scenario.timing.cvs_period_s;
        let end = WARMUP_S + scenario.duration_s + 2.0 * period;
        run(
            "sumo",
            Command::new(&self.sumo)
                .arg("--net-file")
                .arg(&net_file)
                .arg("--route-files")
                .arg(&route_file)
                .arg("--fcd-output")
                .arg(&fcd_file)
                .args(["--step-length", &period.to_string()])
                .args(["--end", &end.to_string()])
                .args(["--seed", &(scenario.seed % (1 << 31)).to_string()])
                .args(["--time-to-teleport", "-1", "--collision.action", "warn"])
                .args(["--precision", "6", "--no-step-log", "true"])
                .args(["--no-warnings", "true"]),
            dir,
        )?;
        fcd_trace(&read(&fcd_file)?, scenario)
    }
}

fn io(what: &str, source: std::io::Error) -> SumoError {
    SumoError::Io {
        what: what.to_owned(),
        source,
    }
}

fn write(path: &Path, text: &str) -> Result<(), SumoError> {
    std::fs::write(path, text).map_err(|e| io(&path.display().to_string(), e))
}

fn read(path: &Path) -> Result<String, SumoError> {
    std::fs::read_to_string(path).map_err(|e| io(&path.display().to_string(), e))
}

/// Runs a SUMO tool in `dir` to its end (at most [`TOOL_TIMEOUT`]), its output in a file.
fn run(tool: &'static str, cmd: &mut Command, dir: &Path) -> Result<(), SumoError> {
    let log_path = dir.join(format!("{tool}.log"));
    let log = std::fs::File::create(&log_path).map_err(|e| io("a tool's log", e))?;
    let err = log.try_clone().map_err(|e| io("a tool's log", e))?;
    let mut child = cmd
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| io(tool, e))?;
    let started = Instant::now();
    let status = loop {
        match child.try_wait().map_err(|e| io(tool, e))? {
            Some(status) if status.success() => return Ok(()),
            Some(status) => break status.to_string(),
            None if started.elapsed() > TOOL_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                break format!("no end within {} s", TOOL_TIMEOUT.as_secs());
            }
            None => std::thread::sleep(Duration::from_millis(10)),
        }
    };
    let printed = std::fs::read_to_string(&log_path).unwrap_or_default();
    let tail: String = printed
        .lines()
        .rev()
        .take(8)
        .collect::<Vec<_>>()
        .join(" | ");
    Err(SumoError::Tool {
        tool,
        status,
        stderr: tail,
    })
}

/// The network's nodes: the scene's road points.
fn nodes(roads: &RoadNetwork) -> String {
    let mut out = String::from("<nodes>\n");
    for (i, p) in roads.points.iter().enumerate() {
        let _ = writeln!(
            out,
            "  <node id=\"p{i}\" x=\"{}\" y=\"{}\" type=\"priority\"/>",
            p[0], p[1]
        );
    }
    out.push_str("</nodes>\n");
    out
}

/// The network's edges: each road piece once per direction it may be driven (`eKf` from its
/// `a` to its `b`, `eKb` back).
fn edges(roads: &RoadNetwork, scenario: &Scenario) -> String {
    let mut out = String::from("<edges>\n");
    let speed = scenario.targets.max_speed_mps;
    let width = roads.lane_offset_m;
    for (k, e) in roads.edges.iter().enumerate() {
        let (a, b) = (e.a, e.b);
        let mut edge = |id: String, from: u32, to: u32| {
            let _ = writeln!(
                out,
                "  <edge id=\"{id}\" from=\"p{from}\" to=\"p{to}\" numLanes=\"1\" \
                 speed=\"{speed}\" width=\"{width}\"/>"
            );
        };
        if e.oneway != Oneway::Backward {
            edge(format!("e{k}f"), a, b);
        }
        if e.oneway != Oneway::Forward {
            edge(format!("e{k}b"), b, a);
        }
    }
    out.push_str("</edges>\n");
    out
}

/// What the routes need of SUMO's network: its edges' lengths and where each leads.
struct Network {
    /// Normal (not internal) edges by id: length, and the edges it connects to.
    edges: BTreeMap<String, (Real, Vec<String>)>,
}

impl Network {
    fn read(xml: &str) -> Result<Network, SumoError> {
        let bad = |what: String| SumoError::Output {
            file: "net.net.xml",
            what,
        };
        let doc = roxmltree::Document::parse(xml).map_err(|e| bad(e.to_string()))?;
        let mut edges: BTreeMap<String, (Real, Vec<String>)> = BTreeMap::new();
        for e in doc.descendants().filter(|n| n.has_tag_name("edge")) {
            if e.attribute("function").is_some() {
                continue;
            }
            let id = e
                .attribute("id")
                .ok_or_else(|| bad("an edge without id".into()))?;
            let length = (e.children().find(|n| n.has_tag_name("lane")))
                .and_then(|lane| lane.attribute("length"))
                .and_then(|l| l.parse::<Real>().ok())
                .ok_or_else(|| bad(format!("edge {id} has no lane length")))?;
            edges.insert(id.to_owned(), (length, Vec::new()));
        }
        for c in doc.descendants().filter(|n| n.has_tag_name("connection")) {
            let (Some(from), Some(to)) = (c.attribute("from"), c.attribute("to")) else {
                continue;
            };
            if edges.contains_key(to)
                && let Some((_, next)) = edges.get_mut(from)
                && !next.iter().any(|n| n == to)
            {
                next.push(to.to_owned());
            }
        }
        Ok(Network { edges })
    }

    /// The largest (by length) strongly connected set of edges, sorted.
    fn loop_edges(&self) -> Vec<String> {
        let ids: Vec<&String> = self.edges.keys().collect();
        let index: BTreeMap<&String, usize> =
            ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        let next: Vec<Vec<usize>> = (ids.iter())
            .map(|id| self.edges[*id].1.iter().map(|n| index[n]).collect())
            .collect();
        let mut prev = vec![Vec::new(); ids.len()];
        for (a, outs) in next.iter().enumerate() {
            for &b in outs {
                prev[b].push(a);
            }
        }
        // Kosaraju: finish order on the graph, then components on the reversed graph.
        let mut order = Vec::with_capacity(ids.len());
        let mut seen = vec![false; ids.len()];
        for start in 0..ids.len() {
            if seen[start] {
                continue;
            }
            seen[start] = true;
            let mut stack = vec![(start, 0usize)];
            while let Some((v, i)) = stack.pop() {
                if let Some(&w) = next[v].get(i) {
                    stack.push((v, i + 1));
                    if !seen[w] {
                        seen[w] = true;
                        stack.push((w, 0));
                    }
                } else {
                    order.push(v);
                }
            }
        }
        let mut component = vec![usize::MAX; ids.len()];
        let mut best: (Real, usize) = (0.0, usize::MAX);
        for (c, &root) in order.iter().rev().enumerate() {
            if component[root] != usize::MAX {
                continue;
            }
            component[root] = c;
            let (mut stack, mut length, mut members) = (vec![root], 0.0, 0);
            while let Some(v) = stack.pop() {
                length += self.edges[ids[v]].0;
                members += 1;
                for &w in &prev[v] {
                    if component[w] == usize::MAX {
                        component[w] = c;
                        stack.push(w);
                    }
                }
            }
            // A lone edge is a loop only if it leads into itself.
            let is_loop = members > 1 || next[root].contains(&root);
            if is_loop && length > best.0 {
                best = (length, c);
            }
        }
        (0..ids.len())
            .filter(|&v| component[v] == best.1)
            .map(|v| ids[v].clone())
            .collect()
    }

    /// A route per car: a start drawn by length, then a random walk over the loop edges.
    fn routes(
        &self,
        scenario: &Scenario,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Vec<String>>, SumoError> {
        let loop_edges = self.loop_edges();
        let on_loop: BTreeSet<&str> = loop_edges.iter().map(String::as_str).collect();
        if loop_edges.len() < 2 {
            return Err(SumoError::NoLoop);
        }
        let length = |e: &str| self.edges[e].0;
        let car = scenario.targets.size_m[0];
        // Start where a car fits with room behind it, where the loop has such edges.
        let roomy: Vec<&String> = (loop_edges.iter())
            .filter(|e| length(e) >= 2.0 * (car + MIN_GAP_M))
            .collect();
        let starts: Vec<&String> = if roomy.is_empty() {
            loop_edges.iter().collect()
        } else {
            roomy
        };
        let total: Real = starts.iter().map(|e| length(e)).sum();
        let need = scenario.targets.max_speed_mps * (WARMUP_S + scenario.duration_s) + 100.0;
        let mut routes = Vec::with_capacity(scenario.targets.count as usize);
        for _ in 0..scenario.targets.count {
            let mut pick = rng.random::<Real>() * total;
            let mut edge = starts[starts.len() - 1];
            for e in &starts {
                pick -= length(e);
                if pick < 0.0 {
                    edge = e;
                    break;
                }
            }
            let mut route = vec![edge.clone()];
            let mut driven = length(edge);
            while driven < need {
                let next: Vec<&String> = (self.edges[route[route.len() - 1].as_str()].1.iter())
                    .filter(|n| on_loop.contains(n.as_str()))
                    .collect();
                let e = next[rng.random_range(0..next.len())];
                driven += length(e);
                route.push(e.clone());
            }
            routes.push(route);
        }
        Ok(routes)
    }
}

/// The route file: the cars' type and each car with its route.
fn route_xml(routes: &[Vec<String>], scenario: &Scenario) -> String {
    let t = &scenario.targets;
    let [length, width, height] = t.size_m;
    let top = t.max_speed_mps * TOP_SPEED_SHARE;
    let mut out = String::from("<routes>\n");
    let _ = writeln!(
        out,
        "  <vType id=\"car\" length=\"{length}\" width=\"{width}\" height=\"{height}\" \
         maxSpeed=\"{top}\" minGap=\"{MIN_GAP_M}\"/>"
    );
    for (i, route) in routes.iter().enumerate() {
        let _ = writeln!(
            out,
            "  <vehicle id=\"c{i}\" type=\"car\" depart=\"0\" departPos=\"random_free\" \
             departLane=\"best\" departSpeed=\"0\">\n    <route edges=\"{}\"/>\n  </vehicle>",
            route.join(" ")
        );
    }
    out.push_str("</routes>\n");
    out
}

/// The trace of SUMO's floating car data: from the first period every car is in, to the run's
/// end.
fn fcd_trace(xml: &str, scenario: &Scenario) -> Result<Trace, SumoError> {
    let bad = |what: String| SumoError::Output {
        file: "fcd.xml",
        what,
    };
    let doc = roxmltree::Document::parse(xml).map_err(|e| bad(e.to_string()))?;
    let cars = scenario.targets.count as usize;
    let period = scenario.timing.cvs_period_s;
    let steps = (scenario.duration_s / period).ceil() as usize + 1;
    let mut points: Vec<Vec<(Real, Real, Real)>> = Vec::new();
    let crowded = |placed| SumoError::Crowded {
        cars: scenario.targets.count,
        placed,
    };
    let mut most = 0;
    for ts in doc.descendants().filter(|n| n.has_tag_name("timestep")) {
        let mut row = vec![None; cars];
        let mut seen = 0;
        for v in ts.children().filter(|n| n.has_tag_name("vehicle")) {
            let number = |name: &str| {
                (v.attribute(name).and_then(|s| s.parse::<Real>().ok()))
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(format!("a vehicle without a number {name}")))
            };
            let car = (v.attribute("id"))
                .and_then(|id| id.strip_prefix('c'))
                .and_then(|n| n.parse::<usize>().ok())
                .filter(|&n| n < cars)
                .ok_or_else(|| bad("a vehicle that is not a car of the run".into()))?;
            // SUMO's angle: degrees clockwise from north.
            let heading = std::f64::consts::FRAC_PI_2 - number("angle")?.to_radians();
            row[car] = Some((number("x")?, number("y")?, heading));
            seen += 1;
        }
        most = most.max(seen);
        let all: Option<Vec<_>> = row.into_iter().collect();
        match all {
            Some(row) => points.push(row),
            None if points.is_empty() => {
                let time = ts.attribute("time").and_then(|t| t.parse::<Real>().ok());
                if time.is_some_and(|t| t > WARMUP_S) {
                    return Err(crowded(most));
                }
                continue;
            }
            None => {
                let time = ts.attribute("time").unwrap_or("?");
                return Err(bad(format!("a car left the network at {time} s")));
            }
        }
        if points.len() == steps {
            return Ok(Trace::from_points(period, &points));
        }
    }
    if points.is_empty() {
        return Err(crowded(most));
    }
    Err(bad(format!(
        "the drive ends after {} periods with every car in, the run needs {steps}",
        points.len()
    )))
}
