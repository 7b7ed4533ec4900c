//! A real single-node Slurm cluster runs the example job files of `examples/cluster/slurm/`
//! as users submit them (only the settings' environment variables are the test's: the
//! binary, the scene path, frames, size, shards and output folder), and its output is
//! compared with a single-machine render.
//!
//! The test starts `munged`, `slurmctld` and `slurmd` itself, without systemd, from a
//! configuration it writes into a temporary folder (free high ports, state, spool, logs and
//! the munge key all there), and stops every one of them by pid when it ends, failing or
//! not ([`Cluster`]'s `Drop`). It needs root (slurmd runs jobs as their user) and Debian's
//! `slurm-wlm` and `munge` (`.ci/run` installs them); without them it prints why it skipped,
//! and fails when `CI` is set.
//!
//! In order:
//! 1. `submit.sh` queues the array (4 shards of 20 frames) and the dependent merge; one
//!    shard is cancelled (`scancel ARRAY_2`) once its first frame is recorded. The other
//!    shards complete, the merge is cancelled by its dependency (never run), and every frame
//!    on disk is whole.
//! 2. `submit.sh` again: the finished shards skip everything, the cancelled one resumes
//!    after its last recorded frame, the merge runs; every frame equals the single
//!    machine's byte for byte, and the records have one line per frame and equal the
//!    single machine's (`common::farm` says which fields are compared).
//! 3. A scene whose frames from 4 on cannot be rendered: `sbatch --wait` of the array
//!    exits non-zero, the failing task leaves the frames before the failure whole and no
//!    other file, and the merge (`sbatch --wait merge.sbatch`) fails naming the missing
//!    frames.

mod common;

use std::collections::BTreeSet;
use std::fs::File;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::farm::{
    FIRST_FAILING_FRAME, MIPRAY, SCENE, assert_complete_sequence, assert_frames_match_reference,
    assert_records_match_reference, example, frame_files, frame_name, frames_arg,
    record_lines_per_frame, render_reference, shard_starts, temporaries, write_failing_scene,
};
use common::shared_data::skip_or_fail;

/// How long any one wait on the cluster may take before the test fails.
const PATIENCE: Duration = Duration::from_secs(120);

/// The Slurm commands the test runs, found on PATH or in the sbin folders.
const PROGRAMS: [&str; 9] = [
    "munged",
    "mungekey",
    "slurmctld",
    "slurmd",
    "sbatch",
    "squeue",
    "scancel",
    "scontrol",
    "sinfo",
];

/// A running single-node cluster: its folder and the daemons the test started.
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    /// Started last first, stopped in reverse.
    daemons: Vec<(&'static str, Child)>,
}

impl Cluster {
    /// Starts munged, slurmctld and slurmd; `Err` says why they cannot run here.
    fn start() -> Result<Cluster, String> {
        if let Some(missing) = PROGRAMS.iter().find(|p| find_program(p).is_none()) {
            return Err(format!(
                "`{missing}` not found: Slurm is not installed (apt-get install slurm-wlm munge)"
            ));
        }
        // SAFETY: geteuid has no preconditions and cannot fail.
        if unsafe { libc::geteuid() } != 0 {
            return Err("not root: slurmd must run as root to start jobs".into());
        }
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        // munged requires every folder on its socket's path to be searchable by all.
        set_mode(dir.path(), 0o711)?;
        let mut cluster = Cluster {
            conf: dir.path().join("slurm.conf"),
            dir,
            daemons: Vec::new(),
        };
        cluster.start_munge()?;
        cluster.write_config()?;
        let conf = cluster.conf.clone();
        let conf = conf.to_str().ok_or("temporary path is not UTF-8")?;
        cluster.spawn("slurmctld", &["-D", "-f", conf])?;
        cluster.spawn("slurmd", &["-D", "-f", conf, "-N", "localhost"])?;
        cluster.wait_until_idle()?;
        Ok(cluster)
    }

    fn path(&self, relative: &str) -> PathBuf {
        self.dir.path().join(relative)
    }

    fn start_munge(&mut self) -> Result<(), String> {
        let munge = self.path("munge");
        std::fs::create_dir(&munge).map_err(|e| e.to_string())?;
        set_mode(&munge, 0o711)?;
        let key = munge.join("munge.key");
        let made = Command::new(find_program("mungekey").unwrap())
            .args(["--create", "--keyfile"])
            .arg(&key)
            .output()
            .map_err(|e| e.to_string())?;
        if !made.status.success() {
            return Err(format!(
                "mungekey: {}",
                String::from_utf8_lossy(&made.stderr)
            ));
        }
        let socket = munge.join("munge.socket");
        let arg = |name: &str, path: PathBuf| format!("--{name}={}", path.display());
        self.spawn(
            "munged",
            &[
                "--foreground",
                &arg("socket", socket.clone()),
                &arg("key-file", key),
                &arg("pid-file", munge.join("munged.pid")),
                &arg("log-file", munge.join("munged.log")),
                &arg("seed-file", munge.join("munged.seed")),
            ],
        )?;
        wait_for(Duration::from_secs(10), || socket.exists())
            .map_err(|_| format!("munged did not start: {}", self.log_tail("munged")))
    }

    fn write_config(&self) -> Result<(), String> {
        for folder in ["state", "spool", "jobs"] {
            std::fs::create_dir(self.path(folder)).map_err(|e| e.to_string())?;
        }
        let [controller, node] = free_ports();
        let p = |relative: &str| self.path(relative).display().to_string();
        // One node of 32 CPUs (SlurmdParameters=config_overrides lets a 2-core machine
        // declare them), so four tasks of the example's --cpus-per-task=8 run at once;
        // process groups instead of cgroups, no accounting, no MPI: what a bare machine has.
        let config = format!(
            "ClusterName=mipraytest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort={controller}
SlurmdPort={node}
AuthType=auth/munge
AuthInfo=socket={socket}
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation={state}
SlurmdSpoolDir={spool}
SlurmctldPidFile={ctld_pid}
SlurmdPidFile={d_pid}
SlurmctldLogFile={ctld_log}
SlurmdLogFile={d_log}
ProctrackType=proctrack/pgid
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
ReturnToService=2
SlurmdParameters=config_overrides
KillWait=2
MinJobAge=600
MailProg=/bin/true
NodeName=localhost NodeAddr=127.0.0.1 CPUs=32 State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
",
            socket = p("munge/munge.socket"),
            state = p("state"),
            spool = p("spool"),
            ctld_pid = p("slurmctld.pid"),
            d_pid = p("slurmd.pid"),
            ctld_log = p("slurmctld.log"),
            d_log = p("slurmd.log"),
        );
        std::fs::write(&self.conf, config).map_err(|e| e.to_string())
    }

    /// Starts a daemon in the foreground (so the test holds its pid), output to NAME.out.
    fn spawn(&mut self, name: &'static str, args: &[&str]) -> Result<(), String> {
        let log = File::create(self.path(&format!("{name}.out"))).map_err(|e| e.to_string())?;
        let err = log.try_clone().map_err(|e| e.to_string())?;
        let child = Command::new(find_program(name).unwrap())
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(err)
            .spawn()
            .map_err(|e| format!("{name}: {e}"))?;
        self.daemons.push((name, child));
        Ok(())
    }

    fn wait_until_idle(&mut self) -> Result<(), String> {
        let idle = wait_for(Duration::from_secs(30), || {
            let state = self.run("sinfo", &["-h", "-N", "-o", "%T"]);
            String::from_utf8_lossy(&state.stdout).trim() == "idle"
        });
        if idle.is_ok() {
            return Ok(());
        }
        let exited = self
            .daemons
            .iter_mut()
            .find_map(|(name, child)| Some((*name, child.try_wait().ok()??)));
        if let Some((name, status)) = exited {
            return Err(format!("{name} exited ({status}): {}", self.log_tail(name)));
        }
        Err(format!(
            "the node did not become idle: {}\n{}",
            self.log_tail("slurmctld"),
            self.log_tail("slurmd")
        ))
    }

    /// The last lines a daemon printed.
    fn log_tail(&self, name: &str) -> String {
        let text = std::fs::read_to_string(self.path(&format!("{name}.out"))).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(15)..].join("\n")
    }

    /// A Slurm command for this cluster, started in its `jobs/` folder (where jobs write
    /// their output files).
    fn command(&self, program: &str) -> Command {
        let path = find_program(program).unwrap_or_else(|| program.into());
        let mut command = Command::new(path);
        command
            .env("SLURM_CONF", &self.conf)
            .current_dir(self.path("jobs"))
            .stdin(Stdio::null());
        command
    }

    fn run(&self, program: &str, args: &[&str]) -> Output {
        self.try_run(program, args)
            .unwrap_or_else(|e| panic!("{program}: {e}"))
    }

    /// [`Self::run`] for `Drop`, which must not panic.
    fn try_run(&self, program: &str, args: &[&str]) -> std::io::Result<Output> {
        self.command(program).args(args).output()
    }

    /// The ids of the jobs still queued or running; none when squeue cannot answer.
    fn queued_jobs(&self) -> BTreeSet<String> {
        self.try_run("squeue", &["-h", "-o", "%A"])
            .map(|q| {
                String::from_utf8_lossy(&q.stdout)
                    .split_whitespace()
                    .map(str::to_string)
                    .collect()
            })
            .unwrap_or_default()
    }

    /// `JobState` of every task of a job (or of one task, `ID_INDEX`), by array index.
    fn states(&self, job: &str) -> Vec<(String, String)> {
        let shown = self.run("scontrol", &["show", "job", "-o", job]);
        let text = String::from_utf8_lossy(&shown.stdout);
        let field = |line: &str, name: &str| {
            line.split_whitespace()
                .find_map(|kv| kv.strip_prefix(name))
                .unwrap_or("")
                .to_string()
        };
        let mut states: Vec<(String, String)> = text
            .lines()
            .map(|l| (field(l, "ArrayTaskId="), field(l, "JobState=")))
            .collect();
        states.sort();
        states
    }

    /// Waits until none of `jobs` is pending or running.
    fn wait_gone(&self, jobs: &[&str]) {
        let list = jobs.join(",");
        wait_for(PATIENCE, || {
            let queued = self.run("squeue", &["-h", "-j", &list, "-o", "%i"]);
            queued.status.success() && queued.stdout.iter().all(u8::is_ascii_whitespace)
        })
        .unwrap_or_else(|_| panic!("jobs {list} still queued after {PATIENCE:?}"));
    }

    /// Text of a job output file in `jobs/`.
    fn job_output(&self, name: &str) -> String {
        std::fs::read_to_string(self.path("jobs").join(name))
            .unwrap_or_else(|e| panic!("job output {name}: {e}"))
    }

    /// Stops a daemon: SIGTERM, then SIGKILL if it has not exited within 5 s.
    fn stop(name: &str, child: &mut Child) {
        let pid = child.id() as libc::pid_t;
        // SAFETY: kill has no memory preconditions; the pid is our own child's, not yet
        // reaped (we hold its Child), so it cannot name another process.
        unsafe { libc::kill(pid, libc::SIGTERM) };
        let exited = wait_for(Duration::from_secs(5), || {
            matches!(child.try_wait(), Ok(Some(_)))
        });
        if exited.is_err() {
            eprintln!("{name} (pid {pid}) ignored SIGTERM; killing it");
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if std::thread::panicking() {
            for name in ["slurmctld", "slurmd", "munged"] {
                eprintln!("--- {name}:\n{}", self.log_tail(name));
            }
        }
        // Jobs first, so slurmd's step daemons end the processes they started; then the
        // daemons, by pid, in the reverse of their start.
        if self.daemons.iter().any(|(name, _)| *name == "slurmctld") {
            let jobs = self.queued_jobs();
            if !jobs.is_empty() {
                eprintln!("cancelling jobs still queued: {jobs:?}");
                let _ = self.command("scancel").args(&jobs).output();
                let _ = wait_for(Duration::from_secs(10), || self.queued_jobs().is_empty());
            }
        }
        while let Some((name, mut child)) = self.daemons.pop() {
            Cluster::stop(name, &mut child);
        }
    }
}

/// `name` on PATH, or in /usr/sbin or /sbin (daemons live there; PATH may lack them).
fn find_program(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin".into(), "/sbin".into()])
        .map(|dir| dir.join(name))
        .find(|candidate| candidate.is_file())
}

fn set_mode(path: &Path, mode: u32) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Two ports free on loopback now (the listeners are dropped before the daemons bind).
fn free_ports() -> [u16; 2] {
    let a = TcpListener::bind("127.0.0.1:0").unwrap();
    let b = TcpListener::bind("127.0.0.1:0").unwrap();
    [
        a.local_addr().unwrap().port(),
        b.local_addr().unwrap().port(),
    ]
}

/// Polls `done` every 100 ms until it holds (`Ok`) or `limit` passes (`Err`).
fn wait_for(limit: Duration, mut done: impl FnMut() -> bool) -> Result<(), ()> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if done() {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    if done() { Ok(()) } else { Err(()) }
}

/// The settings `submit.sh` reads from the environment: the test's paths and sizes.
fn settings(
    scene: &Path,
    frames: &str,
    size: &str,
    out: &Path,
    shards: u32,
) -> Vec<(String, String)> {
    [
        ("MIPRAY", MIPRAY.to_string()),
        ("MIPRAY_SCENE", scene.display().to_string()),
        ("MIPRAY_FRAMES", frames.to_string()),
        ("MIPRAY_SIZE", size.to_string()),
        ("MIPRAY_OUT", out.display().to_string()),
        ("MIPRAY_SHARDS", shards.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// Runs `submit.sh`; the array job's and the merge job's ids.
fn submit(cluster: &Cluster, env: &[(String, String)]) -> (String, String) {
    let output = cluster
        .command("bash")
        .arg(example("slurm/submit.sh"))
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .expect("run submit.sh");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "submit.sh failed: {stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let id_after = |prefix: &str| {
        stdout
            .lines()
            .find_map(|l| l.strip_prefix(prefix))
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or_else(|| panic!("submit.sh printed no `{prefix}`: {stdout}"))
            .to_string()
    };
    (id_after("render: array job "), id_after("merge: job "))
}

/// Frames recorded in a shard's stats file.
fn recorded(dir: &Path, shard: u32, shards: u32) -> BTreeSet<u32> {
    let path = dir.join(format!("stats.shard-{shard}-of-{shards}.jsonl"));
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| mipray::record::Record::parse(l).ok())
        .filter(|r| r.missing().is_empty())
        .map(|r| r.frame())
        .collect()
}

#[test]
fn example_slurm_jobs_render_resume_and_fail_visibly() {
    let started = Instant::now();
    let cluster = match Cluster::start() {
        Ok(cluster) => cluster,
        Err(reason) => {
            skip_or_fail(&format!("no Slurm cluster: {reason}"));
            return;
        }
    };
    println!("cluster up in {:.1} s", started.elapsed().as_secs_f64());
    let frames = 0..20;
    // Frames large enough that the cancel (a poll of up to 100 ms, then `scancel`) lands
    // while the shard still has frames to render: at 320x180 a frame of the default
    // animation takes under 20 ms on a fast CPU, and a shard's last four frames could finish
    // before the cancel arrived. At 1280x720 a frame takes 16 times as long (about 0.3 s on
    // one core, more with the four shards sharing the machine's cores).
    let (size, shards, cancelled) = ("1280x720", 4, 2);
    let reference = cluster.path("reference");
    render_reference(&frames, size, &reference);

    // 1. The whole pipeline, one shard cancelled mid-sequence.
    let out = cluster.path("farm");
    let env = settings(Path::new(SCENE), &frames_arg(&frames), size, &out, shards);
    let (array, merge) = submit(&cluster, &env);
    wait_for(PATIENCE, || !recorded(&out, cancelled, shards).is_empty())
        .unwrap_or_else(|_| panic!("shard {cancelled} recorded no frame"));
    let task = format!("{array}_{cancelled}");
    let scancel = cluster.run("scancel", &[&task]);
    assert!(scancel.status.success(), "scancel {task}: {scancel:?}");
    cluster.wait_gone(&[&array, &merge]);
    let states = cluster.states(&array);
    let expected: Vec<(String, String)> = (0..shards)
        .map(|i| {
            let state = if i == cancelled {
                "CANCELLED"
            } else {
                "COMPLETED"
            };
            (i.to_string(), state.to_string())
        })
        .collect();
    assert_eq!(states, expected, "array {array} after scancel {task}");
    // The merge never ran: its dependency can no longer be met.
    assert_eq!(
        cluster.states(&merge),
        [(String::new(), "CANCELLED".to_string())]
    );
    assert!(
        !out.join("report.svg").exists(),
        "the merge ran after a cancelled shard"
    );
    // The cancel landed mid-sequence, and what is on disk is whole.
    let before_resume = recorded(&out, cancelled, shards);
    let on_disk = assert_frames_match_reference(&reference, &out);
    assert!(
        on_disk.len() < frames.len(),
        "shard {cancelled} finished before its cancel landed: nothing left to resume"
    );
    let left_behind = temporaries(&out);
    println!(
        "after scancel {task}: shard {cancelled} had recorded {before_resume:?}; {} of {} frames on disk; temporaries {left_behind:?}",
        on_disk.len(),
        frames.len()
    );

    // 2. Submitted again: only the missing frames are rendered, then the merge runs.
    let (array, merge) = submit(&cluster, &env);
    cluster.wait_gone(&[&array, &merge]);
    let all_done: Vec<(String, String)> = (0..shards)
        .map(|i| (i.to_string(), "COMPLETED".to_string()))
        .collect();
    assert_eq!(
        cluster.states(&array),
        all_done,
        "resubmitted array {array}"
    );
    assert_eq!(
        cluster.states(&merge),
        [(String::new(), "COMPLETED".to_string())]
    );
    let merged = cluster.job_output(&format!("mipray-merge-{merge}.out"));
    assert!(
        merged.contains(&format!("complete: every frame of {}", frames_arg(&frames))),
        "merge output: {merged}"
    );
    assert!(out.join("report.svg").is_file() && out.join("index.html").is_file());
    assert_complete_sequence(&reference, &out, &frames);
    // Where processes started: each shard's first frame, and the cancelled shard's first
    // frame without a record (its resumed task's first).
    let block = recorded(&out, cancelled, shards);
    let resumed_at = *block
        .difference(&before_resume)
        .next()
        .expect("the cancelled shard had frames left");
    assert!(before_resume.iter().all(|f| *f < resumed_at));
    let mut first_frames = shard_starts(&out);
    first_frames.insert(resumed_at);
    assert_records_match_reference(&reference, &out, &frames, Some(&first_frames));
    let resumed_log = cluster.job_output(&format!("mipray-render-{array}_{cancelled}.out"));
    assert!(
        resumed_log.contains(&format!(
            "resuming: {} of {} frame(s) already complete",
            before_resume.len(),
            block.len()
        )),
        "resumed shard's output: {resumed_log}"
    );
    assert_eq!(
        record_lines_per_frame(&out).values().sum::<usize>(),
        frames.len()
    );

    // 3. A task whose frames fail: the array fails visibly, nothing half-written remains.
    let failing = write_failing_scene(&cluster.path("."));
    let out = cluster.path("failing");
    let fail_frames = 0..6;
    let env = settings(&failing, &frames_arg(&fail_frames), "32x18", &out, 2);
    std::fs::create_dir_all(&out).unwrap();
    let waited = cluster
        .command("sbatch")
        .args(["--wait", "--parsable", "--array=0-1"])
        .arg(example("slurm/render.sbatch"))
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .expect("sbatch --wait");
    let failed_array = String::from_utf8_lossy(&waited.stdout).trim().to_string();
    assert!(
        !waited.status.success(),
        "sbatch --wait exited 0 though a task failed"
    );
    assert_eq!(
        cluster.states(&failed_array),
        [
            ("0".to_string(), "COMPLETED".to_string()),
            ("1".to_string(), "FAILED".to_string())
        ]
    );
    let log = cluster.job_output(&format!("mipray-render-{failed_array}_1.out"));
    assert!(
        log.contains(&format!("overflowing.gltf: frame {FIRST_FAILING_FRAME} "))
            && log.contains("error: ")
            && log.contains("non-finite vertex"),
        "failed task's output: {log}"
    );
    // Shard 1 (frames 3..6) wrote frame 3, then failed on 4: frames 0..4 are on disk,
    // each a whole PNG, and no temporary file.
    let expected: BTreeSet<String> = (0..FIRST_FAILING_FRAME).map(frame_name).collect();
    assert_eq!(frame_files(&out), expected);
    for name in &expected {
        image::open(out.join(name)).unwrap_or_else(|e| panic!("{name} is not a whole PNG: {e}"));
    }
    assert_eq!(temporaries(&out), Vec::<String>::new());
    // The merge fails and names the frames that are missing.
    let merge = cluster
        .command("sbatch")
        .args(["--wait", "--parsable"])
        .arg(example("slurm/merge.sbatch"))
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .expect("sbatch --wait merge");
    assert!(
        !merge.status.success(),
        "the merge of an incomplete sequence exited 0"
    );
    let merge_id = String::from_utf8_lossy(&merge.stdout).trim().to_string();
    let merged = cluster.job_output(&format!("mipray-merge-{merge_id}.out"));
    assert!(
        merged.contains(&format!(
            "2 frame(s) of 0..6 have no record or no frame file: {FIRST_FAILING_FRAME}..6"
        )),
        "merge output: {merged}"
    );
    println!(
        "Slurm test done in {:.1} s",
        started.elapsed().as_secs_f64()
    );
}
