//! The Slurm queue, through its commands only (no accounting database): submitting a
//! job script (`sbatch --parsable`), following jobs (one `squeue` for all of them,
//! falling back to `scontrol show job` for a job squeue no longer lists), cancelling
//! them (`scancel`); and the parsers of what those commands print, which are pure.
//! A job neither command knows any more, and which wrote no exit-code file, is
//! [`JobState::Lost`].

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Where a job is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum JobState {
    /// Waiting in the queue, and why (Slurm's reason: `Priority`, `Resources`, ...).
    Pending {
        reason: String,
    },
    Running,
    Completed,
    Failed,
    TimedOut,
    Cancelled,
    /// Neither squeue nor scontrol knows it (purged, or a restarted controller).
    Lost,
}

impl JobState {
    /// Whether the job has ended (for better or worse).
    pub fn is_final(&self) -> bool {
        !matches!(self, JobState::Pending { .. } | JobState::Running)
    }

    /// The state of Slurm's word for it (`PENDING`, `CANCELLED by 0`, `NODE_FAIL`, ...).
    fn of(word: &str, reason: &str) -> JobState {
        match word.split_whitespace().next().unwrap_or("") {
            "PENDING" | "PD" | "REQUEUED" | "RQ" | "CONFIGURING" | "CF" | "SUSPENDED" | "S"
            | "REQUEUE_HOLD" | "REQUEUE_FED" => JobState::Pending {
                reason: reason.to_owned(),
            },
            "RUNNING" | "R" | "COMPLETING" | "CG" | "STAGE_OUT" | "SO" => JobState::Running,
            "COMPLETED" | "CD" => JobState::Completed,
            "TIMEOUT" | "TO" | "DEADLINE" | "DL" => JobState::TimedOut,
            "CANCELLED" | "CA" | "PREEMPTED" | "PR" => JobState::Cancelled,
            _ => JobState::Failed,
        }
    }
}

/// What the queue says of one job.
#[derive(Clone, Debug, PartialEq)]
pub struct JobInfo {
    pub state: JobState,
    /// The nodes it runs or ran on, as Slurm writes them (`n[1-2]`); empty while pending.
    pub nodes: String,
    /// Seconds from submission to start, once it started.
    pub queue_wait_s: Option<f64>,
}

impl JobInfo {
    fn lost() -> JobInfo {
        JobInfo {
            state: JobState::Lost,
            nodes: String::new(),
            queue_wait_s: None,
        }
    }
}

/// The `squeue` output format [`parse_squeue`] reads: id, state, reason, nodes, submit
/// and start times, separated by `|`.
pub const SQUEUE_FORMAT: &str = "%i|%T|%r|%N|%V|%S";

/// Each job `squeue -h -o SQUEUE_FORMAT` lists, by id.
pub fn parse_squeue(text: &str) -> BTreeMap<String, JobInfo> {
    text.lines()
        .filter_map(|line| {
            let fields: Vec<&str> = line.trim().split('|').collect();
            let [id, state, reason, nodes, submit, start] = fields[..] else {
                return None;
            };
            let info = JobInfo {
                state: JobState::of(state, reason),
                nodes: nodes.to_owned(),
                queue_wait_s: wait(submit, start),
            };
            Some((id.to_owned(), info))
        })
        .collect()
}

/// What `scontrol show job ID` says of the job (its `KEY=VALUE` words), if anything.
pub fn parse_scontrol(text: &str) -> Option<JobInfo> {
    let fields: BTreeMap<&str, &str> = text
        .split_whitespace()
        .filter_map(|word| word.split_once('='))
        .collect();
    let state = fields.get("JobState")?;
    Some(JobInfo {
        state: JobState::of(state, fields.get("Reason").copied().unwrap_or("")),
        nodes: fields
            .get("NodeList")
            .filter(|&&nodes| nodes != "(null)")
            .map_or_else(String::new, |nodes| (*nodes).to_owned()),
        queue_wait_s: wait(
            fields.get("SubmitTime").copied().unwrap_or(""),
            fields.get("StartTime").copied().unwrap_or(""),
        ),
    })
}

/// Seconds from `submit` to `start` (Slurm's `YYYY-MM-DDTHH:MM:SS`), when both are
/// times and the start is not in the future of a pending job's estimate.
fn wait(submit: &str, start: &str) -> Option<f64> {
    let (submit, start) = (epoch_seconds(submit)?, epoch_seconds(start)?);
    (start >= submit).then(|| (start - submit) as f64)
}

/// `YYYY-MM-DDTHH:MM:SS` as seconds since 1970 (the clock's own zone: only differences
/// are used).
fn epoch_seconds(text: &str) -> Option<i64> {
    let (date, time) = text.split_once('T')?;
    let d: Vec<i64> = date
        .split('-')
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    let t: Vec<i64> = time
        .split(':')
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    let (&[y, m, day], &[hh, mm, ss]) = (&d[..], &t[..]) else {
        return None;
    };
    // Days from the civil date (Howard Hinnant's algorithm).
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    Some(days * 86_400 + hh * 3600 + mm * 60 + ss)
}

/// Submits the job script at `script`; its id, or sbatch's own words when it refuses.
pub fn submit(script: &Path) -> Result<String, String> {
    let output = Command::new("sbatch")
        .arg("--parsable")
        .arg(script)
        .output()
        .map_err(|e| {
            format!("cannot run sbatch: {e}; is Slurm's client installed and on the PATH?")
        })?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    // --parsable prints `ID` or `ID;CLUSTER`.
    let id = stdout.trim().split(';').next().unwrap_or("").to_owned();
    if !output.status.success() || id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(format!(
            "sbatch refused {} ({}): {}",
            script.display(),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        ));
    }
    Ok(id)
}

/// What the queue says of each of `ids`: one `squeue` for all, then `scontrol show job`
/// for each it does not list; [`JobState::Lost`] where neither knows it.
pub fn poll(ids: &[String]) -> BTreeMap<String, JobInfo> {
    if ids.is_empty() {
        return BTreeMap::new();
    }
    let listed = Command::new("squeue")
        .args(["-h", "-t", "all", "-o", SQUEUE_FORMAT, "-j", &ids.join(",")])
        .output()
        .ok()
        .filter(|output| output.status.success())
        .map(|output| parse_squeue(&String::from_utf8_lossy(&output.stdout)))
        .unwrap_or_default();
    ids.iter()
        .map(|id| {
            let info = listed.get(id).cloned().unwrap_or_else(|| {
                Command::new("scontrol")
                    .args(["show", "job", id])
                    .output()
                    .ok()
                    .filter(|output| output.status.success())
                    .and_then(|output| parse_scontrol(&String::from_utf8_lossy(&output.stdout)))
                    .unwrap_or_else(JobInfo::lost)
            });
            (id.clone(), info)
        })
        .collect()
}

/// Cancels `ids` (those already ended are ignored by Slurm); false when scancel failed.
pub fn cancel(ids: &[String]) -> bool {
    ids.is_empty()
        || Command::new("scancel")
            .args(ids)
            .status()
            .is_ok_and(|status| status.success())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squeue_lines_give_each_jobs_state_nodes_and_wait() {
        let text = "\
12|PENDING|Resources||2026-11-29T04:00:00|N/A
13|RUNNING|None|n[1-2]|2026-11-29T04:00:00|2026-11-29T04:00:07
14|TIMEOUT|TimeLimit|n1|2026-11-29T23:59:50|2026-11-30T00:00:10
15|CANCELLED by 0|None|n1|2026-11-29T04:00:00|2026-11-29T04:00:01
16|OUT_OF_MEMORY|OutOfMemory|n2|2026-11-29T04:00:00|2026-11-29T04:00:01
garbage";
        let jobs = parse_squeue(text);
        assert_eq!(jobs.len(), 5);
        assert_eq!(
            jobs["12"].state,
            JobState::Pending {
                reason: "Resources".into()
            }
        );
        assert_eq!(jobs["12"].queue_wait_s, None);
        assert_eq!(
            (jobs["13"].state.clone(), jobs["13"].nodes.as_str()),
            (JobState::Running, "n[1-2]")
        );
        assert_eq!(jobs["13"].queue_wait_s, Some(7.0));
        // Across midnight.
        assert_eq!(jobs["14"].queue_wait_s, Some(20.0));
        assert_eq!(jobs["14"].state, JobState::TimedOut);
        assert_eq!(jobs["15"].state, JobState::Cancelled);
        assert_eq!(jobs["16"].state, JobState::Failed);
        assert!(jobs["16"].state.is_final() && !jobs["13"].state.is_final());
    }

    #[test]
    fn scontrol_gives_a_finished_jobs_state_and_an_unknown_id_gives_nothing() {
        let text = "JobId=21 JobName=collide-x\n   JobState=COMPLETED Reason=None Dependency=(null)\n   \
                    SubmitTime=2026-11-29T04:00:00 EligibleTime=2026-11-29T04:00:00\n   \
                    StartTime=2026-11-29T04:00:02 EndTime=2026-11-29T04:00:03\n   NodeList=n[1-2]\n";
        let info = parse_scontrol(text).unwrap();
        assert_eq!(info.state, JobState::Completed);
        assert_eq!(
            (info.nodes.as_str(), info.queue_wait_s),
            ("n[1-2]", Some(2.0))
        );
        let pending =
            parse_scontrol("JobId=22 JobState=PENDING Reason=Priority NodeList=(null)").unwrap();
        assert_eq!(
            (pending.state, pending.nodes.as_str()),
            (
                JobState::Pending {
                    reason: "Priority".into()
                },
                ""
            )
        );
        assert_eq!(
            parse_scontrol("slurm_load_jobs error: Invalid job id specified"),
            None
        );
    }
}
