//! Measures the ROS pipeline across processes: end-to-end latency from /scan publication to
//! /human/activity reception (p50, p99) with replay, localiser and classifier as three
//! processes over DDS, and each node's CPU share and peak RSS, at 1x and faster replay rates
//! up to as fast as possible (rate 0). Runs itself inside a private network namespace
//! (nothing leaves loopback).
//!
//!     cargo build --release -p lidar_har -p lidar-har-cli --bins --examples
//!     target/release/lidar-har simulate --duration 200 --out /tmp/sim200
//!     target/release/examples/latency --bag /tmp/sim200 --model models/activity.onnx \
//!         [--seconds 20] [--rates 1,20,50,0]
//!
//! BAG is a simulated bag with /map, /odom, /tf and /scan (e.g. from `lidar-har simulate`),
//! long enough for the start-up and `--seconds` of measurement at 1x. The classifier needs
//! ONNX Runtime (`ORT_DYLIB_PATH`). Latency is from the source time stamp replay's DDS writer
//! gives a /scan to the arrival of the /human/activity with that scan's stamp at this probe.
//! CPU counts from the replay's start (the other nodes have been up for 1.5 s) to the end of
//! the run (`--seconds` at most, or when the activities stopped after the replay ended);
//! RSS is the peak over the whole run.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use lidar_har_core::stats::nearest_rank;
use lidar_har_msgs::lidar_har_msgs::Activity;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::topics;
use lidar_har_ros::{Node, NodeSetup};

const NETNS_ENV: &str = "LIDAR_HAR_LATENCY_IN_NETNS";

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("latency: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

struct Args {
    bag: PathBuf,
    model: Option<PathBuf>,
    seconds: f64,
    /// Replay rates to measure; 0 = as fast as possible.
    rates: Vec<f64>,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = std::env::args().skip(1);
    let (mut bag, mut model, mut seconds) = (None, None, 20.0);
    let mut rates = vec![1.0, 20.0, 50.0, 0.0];
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--bag" => bag = Some(PathBuf::from(value()?)),
            "--model" => model = Some(PathBuf::from(value()?)),
            "--seconds" => seconds = value()?.parse().context("--seconds")?,
            "--rates" => {
                rates = value()?
                    .split(',')
                    .map(|r| match r.trim().parse::<f64>() {
                        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
                        _ => bail!("--rates: {r:?} is not a rate >= 0"),
                    })
                    .collect::<anyhow::Result<_>>()?
            }
            other => bail!(
                "unknown argument {other}; usage: latency --bag BAG [--model M] [--seconds S] [--rates 1,10,0]"
            ),
        }
    }
    Ok(Args {
        bag: bag.context("--bag BAG is required")?,
        model,
        seconds,
        rates,
    })
}

fn run() -> anyhow::Result<()> {
    if std::env::var_os(NETNS_ENV).is_none() {
        // Re-run inside a fresh network namespace with a multicast loopback.
        let me = std::env::current_exe()?;
        let status = Command::new("unshare")
            .args(["-rn", "sh", "-c"])
            .arg(
                "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec \"$0\" \"$@\"",
            )
            .arg(me)
            .args(std::env::args().skip(1))
            .env(NETNS_ENV, "1")
            .status()
            .context("unshare -rn (a private network namespace is needed)")?;
        if !status.success() {
            bail!("the measurement inside the namespace failed ({status})");
        }
        return Ok(());
    }
    let args = parse_args()?;
    let bins = std::env::current_exe()?
        .parent()
        .and_then(Path::parent)
        .context("binary directory")?
        .to_path_buf();
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{} CPUs, load average {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!(
        "| replay rate | scans seen | activities (window) | latency p50 | latency p99 | node | CPU (% of one core) | peak RSS |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &rate in &args.rates {
        measure(&bins, &args, rate)?;
    }
    Ok(())
}

fn spawn(bins: &Path, name: &str, params: &[String]) -> anyhow::Result<Child> {
    let mut cmd = Command::new(bins.join(name));
    if std::env::var_os("RUST_LOG").is_none() {
        cmd.env("RUST_LOG", "warn");
    }
    cmd.arg("--ros-args");
    for p in params {
        cmd.args(["-p", p]);
    }
    cmd.spawn()
        .with_context(|| format!("start {} (build with --bins)", bins.join(name).display()))
}

/// utime + stime of a process, in clock ticks.
fn cpu_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    Some(fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?)
}

/// Whether a process has exited but not been reaped.
fn is_zombie(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|stat| Some(stat.rsplit_once(')')?.1.trim_start().starts_with('Z')))
        .unwrap_or(false)
}

/// Peak resident set size, kB.
fn peak_rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
}

fn wall_clock_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// How long the nodes get to start (DDS discovery, ONNX Runtime) before the replay begins.
const START_UP: Duration = Duration::from_millis(1500);
/// After the replay ended, the run is over once no activity came for this long.
const DRAIN: Duration = Duration::from_millis(500);
/// No activity at all within this time (after the start-up) is an error.
const FIRST_ACTIVITY_TIMEOUT: Duration = Duration::from_secs(15);

const NODES: [&str; 3] = ["replay", "localiser", "classifier"];

/// One run: latency of every /human/activity whose scan the probe saw published, and CPU
/// ticks and peak RSS of each node.
fn measure(bins: &Path, args: &Args, rate: f64) -> anyhow::Result<()> {
    let node = Node::new(NodeSetup::new("latency_probe").args(Vec::<String>::new()))?;
    let scans = node.subscriber_for(&topics::SCAN)?;
    let activities = node.subscriber_for(&topics::HUMAN_ACTIVITY)?;
    let mut classifier_params = Vec::new();
    if let Some(m) = &args.model {
        classifier_params.push(format!("model:={}", m.display()));
    }
    let localiser = spawn(bins, "localiser", &[])?;
    let classifier = spawn(bins, "classifier", &classifier_params)?;
    std::thread::sleep(START_UP);
    let replay = spawn(
        bins,
        "replay",
        &[
            format!("bag:={}", args.bag.display()),
            format!("rate:={rate}"),
            "wait_for_subscriber:=/scan".into(),
        ],
    )?;
    let mut children = [replay, localiser, classifier];
    let replay_started = (Instant::now(), cpu_all(&children));
    let result = observe(
        &node,
        &scans,
        &activities,
        &mut children,
        replay_started,
        args,
        rate,
    );
    for child in &mut children {
        let _ = child.kill();
        let _ = child.wait();
    }
    let run = result?;
    let mut latencies_ms = run.latencies_ms;
    latencies_ms.sort_by(f64::total_cmp);
    let label = if rate > 0.0 {
        format!("{rate}x")
    } else {
        "max".into()
    };
    for (i, name) in NODES.iter().enumerate() {
        let cpu = match (run.cpu_end[i], run.cpu_start[i]) {
            (Some(c1), Some(c0)) => {
                c1.saturating_sub(c0) as f64 / TICKS_PER_S / run.window_s * 100.0
            }
            _ => f64::NAN,
        };
        let (l, s, a, p50, p99) = if i == 0 {
            (
                label.clone(),
                run.scans.to_string(),
                format!("{} ({:.1} s)", run.activities, run.window_s),
                format!(
                    "{:.2} ms",
                    nearest_rank(&latencies_ms, 0.5).unwrap_or(f64::NAN)
                ),
                format!(
                    "{:.2} ms",
                    nearest_rank(&latencies_ms, 0.99).unwrap_or(f64::NAN)
                ),
            )
        } else {
            Default::default()
        };
        println!(
            "| {l} | {s} | {a} | {p50} | {p99} | {name} | {cpu:.1} | {:.1} MB |",
            run.peak_rss_kb[i] as f64 / 1024.0
        );
    }
    Ok(())
}

fn cpu_all(children: &[Child; 3]) -> Vec<Option<u64>> {
    children.iter().map(|c| cpu_ticks(c.id())).collect()
}

/// USER_HZ on Linux: the unit of /proc/PID/stat's utime and stime.
const TICKS_PER_S: f64 = 100.0;

struct Run {
    scans: u64,
    activities: u64,
    latencies_ms: Vec<f64>,
    window_s: f64,
    cpu_start: Vec<Option<u64>>,
    cpu_end: Vec<Option<u64>>,
    peak_rss_kb: [u64; 3],
}

fn observe(
    node: &Node,
    scans: &lidar_har_ros::Subscriber,
    activities: &lidar_har_ros::Subscriber,
    children: &mut [Child; 3],
    (window_start, cpu_start): (Instant, Vec<Option<u64>>),
    args: &Args,
    rate: f64,
) -> anyhow::Result<Run> {
    let mut published: HashMap<i64, i64> = HashMap::new();
    let mut latencies_ms = Vec::new();
    let (mut n_scans, mut n_activities) = (0u64, 0u64);
    let mut peak_rss = [0u64; 3];
    let mut last_activity: Option<Instant> = None;
    let mut replay_ended: Option<Instant> = None;
    let window_end = loop {
        while let Some((scan, sample)) = scans.try_take_msg::<LaserScan>()? {
            n_scans += 1;
            if let Some(t) = sample.source_time_ns {
                published.insert(scan.header.stamp.to_nanos(), t);
            }
        }
        while let Some((activity, _)) = activities.try_take_msg::<Activity>()? {
            let now = wall_clock_ns();
            last_activity = Some(Instant::now());
            n_activities += 1;
            if let Some(sent) = published.get(&activity.header.stamp.to_nanos()) {
                latencies_ms.push((now - sent) as f64 / 1e6);
            }
        }
        // VmHWM is gone once a process has exited: sample it while they run.
        for (peak, child) in peak_rss.iter_mut().zip(children.iter()) {
            if let Some(kb) = peak_rss_kb(child.id()) {
                *peak = (*peak).max(kb);
            }
        }
        for (name, child) in NODES.iter().zip(children.iter_mut()).skip(1) {
            if let Some(status) = child.try_wait()? {
                bail!("{name} exited during the measurement ({status})");
            }
        }
        // Not reaped yet (a zombie keeps its CPU times readable); its status is read below.
        if replay_ended.is_none() && is_zombie(children[0].id()) {
            replay_ended = Some(Instant::now());
        }
        let now = Instant::now();
        if rate > 0.0 && now.duration_since(window_start).as_secs_f64() >= args.seconds {
            break now;
        }
        if let Some(ended) = replay_ended {
            // Done once the activities stopped coming after the replay ended; the idle tail
            // is left out of the window.
            let quiet_since = last_activity.map_or(ended, |t| t.max(ended));
            if now.duration_since(quiet_since) >= DRAIN {
                break quiet_since;
            }
        }
        if last_activity.is_none()
            && rate > 0.0
            && now.duration_since(window_start) > FIRST_ACTIVITY_TIMEOUT
        {
            bail!(
                "no /human/activity within {FIRST_ACTIVITY_TIMEOUT:?} ({n_scans} scans seen): is the person tracked, the model loadable?"
            );
        }
        node.wait(Duration::from_millis(20))?;
    };
    let cpu_end = cpu_all(children);
    if replay_ended.is_some() {
        let status = children[0].wait()?;
        if !status.success() {
            bail!("replay failed ({status})");
        }
    }
    Ok(Run {
        scans: n_scans,
        activities: n_activities,
        latencies_ms,
        window_s: window_end.duration_since(window_start).as_secs_f64(),
        cpu_start,
        cpu_end,
        peak_rss_kb: peak_rss,
    })
}
