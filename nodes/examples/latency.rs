//! Measures the ROS pipeline across processes: end-to-end latency from /scan publication to
//! /human/activity reception (p50, p99) with replay, localiser and classifier as three
//! processes over DDS, and each node's CPU share and peak RSS, at 1x and at maximum replay
//! speed. Runs itself inside a private network namespace (nothing leaves loopback).
//!
//!     cargo build --release -p lidar_har --bins --examples
//!     target/release/examples/latency --bag BAG [--model models/activity.onnx] [--seconds 20]
//!
//! BAG is a simulated bag with /map, /odom, /tf and /scan (e.g. from `lidar-har simulate`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
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
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = std::env::args().skip(1);
    let (mut bag, mut model, mut seconds) = (None, None, 20.0);
    while let Some(a) = args.next() {
        let mut value = || args.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--bag" => bag = Some(PathBuf::from(value()?)),
            "--model" => model = Some(PathBuf::from(value()?)),
            "--seconds" => seconds = value()?.parse().context("--seconds")?,
            other => bail!(
                "unknown argument {other}; usage: latency --bag BAG [--model M] [--seconds S]"
            ),
        }
    }
    Ok(Args {
        bag: bag.context("--bag BAG is required")?,
        model,
        seconds,
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
    println!(
        "| replay rate | scans | activities | latency p50 | latency p99 | node | CPU (% of one core) | peak RSS |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for rate in [1.0, 0.0] {
        measure(&bins, &args, rate)?;
    }
    Ok(())
}

fn spawn(bins: &Path, name: &str, params: &[String]) -> anyhow::Result<Child> {
    let mut cmd = Command::new(bins.join(name));
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

/// Peak resident set size, kB.
fn peak_rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1]
}

fn measure(bins: &Path, args: &Args, rate: f64) -> anyhow::Result<()> {
    let node = Node::new(NodeSetup::new("latency_probe").args(Vec::<String>::new()))?;
    let scans = node.subscriber_for(&topics::SCAN)?;
    let activities = node.subscriber_for(&topics::HUMAN_ACTIVITY)?;
    let mut classifier_params = Vec::new();
    if let Some(m) = &args.model {
        classifier_params.push(format!("model:={}", m.display()));
    }
    let mut localiser = spawn(bins, "localiser", &[])?;
    let mut classifier = spawn(bins, "classifier", &classifier_params)?;
    let mut replay = spawn(
        bins,
        "replay",
        &[
            format!("bag:={}", args.bag.display()),
            format!("rate:={rate}"),
            "wait_for_subscriber:=/scan".into(),
        ],
    )?;
    let ticks_per_s = 100.0; // USER_HZ on Linux
    let start = Instant::now();
    let cpu0: Vec<Option<u64>> = [&replay, &localiser, &classifier]
        .iter()
        .map(|c| cpu_ticks(c.id()))
        .collect();
    let mut published: HashMap<i64, i64> = HashMap::new();
    let mut latencies_ms = Vec::new();
    let (mut n_scans, mut n_activities) = (0u64, 0u64);
    let deadline = start + Duration::from_secs_f64(args.seconds);
    let mut replay_done = false;
    while Instant::now() < deadline && !replay_done {
        while let Some((scan, sample)) = scans.try_take_msg::<LaserScan>()? {
            n_scans += 1;
            if let Some(t) = sample.source_time_ns {
                published.insert(scan.header.stamp.to_nanos(), t);
            }
        }
        while let Some((activity, _)) = activities.try_take_msg::<Activity>()? {
            n_activities += 1;
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)?
                .as_nanos() as i64;
            if let Some(sent) = published.get(&activity.header.stamp.to_nanos()) {
                latencies_ms.push((now - sent) as f64 / 1e6);
            }
        }
        node.wait(Duration::from_millis(20))?;
        replay_done = replay.try_wait()?.is_some();
    }
    let elapsed = start.elapsed().as_secs_f64();
    let children = [
        ("replay", &mut replay),
        ("localiser", &mut localiser),
        ("classifier", &mut classifier),
    ];
    let usage: Vec<(String, f64, u64)> = children
        .iter()
        .zip(&cpu0)
        .map(|((name, child), c0)| {
            let cpu = match (cpu_ticks(child.id()), c0) {
                (Some(c1), Some(c0)) => (c1 - c0) as f64 / ticks_per_s / elapsed * 100.0,
                _ => f64::NAN,
            };
            (name.to_string(), cpu, peak_rss_kb(child.id()).unwrap_or(0))
        })
        .collect();
    for (_, child) in children {
        let _ = child.kill();
        let _ = child.wait();
    }
    latencies_ms.sort_by(f64::total_cmp);
    let label = if rate > 0.0 {
        format!("{rate}x")
    } else {
        "max".into()
    };
    for (i, (name, cpu, rss)) in usage.iter().enumerate() {
        let (l, s, a, p50, p99) = if i == 0 {
            (
                label.clone(),
                n_scans.to_string(),
                n_activities.to_string(),
                format!("{:.2} ms", quantile(&latencies_ms, 0.5)),
                format!("{:.2} ms", quantile(&latencies_ms, 0.99)),
            )
        } else {
            Default::default()
        };
        println!(
            "| {l} | {s} | {a} | {p50} | {p99} | {name} | {cpu:.1} | {:.1} MB |",
            *rss as f64 / 1024.0
        );
    }
    Ok(())
}
