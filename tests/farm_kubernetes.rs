//! The Kubernetes example (`examples/cluster/kubernetes/`), without a cluster: no
//! Kubernetes can run on the test machine, so the Indexed Job is emulated as Kubernetes
//! runs it. One process per index, all at once, each with a container's bare environment
//! (the manifest's `env` plus `JOB_COMPLETION_INDEX`, which Kubernetes sets), running the
//! container's `command` read from `job.yaml`, with the volume's mount path mapped to a
//! temporary folder and only the frames and size made small; the working folder holds
//! `animations/` as the image's does. One pod is killed mid-sequence and started again
//! (what the Job does for a failed pod), then `merge-job.yaml`'s command runs, and the
//! output must equal a single-machine render.
//!
//! Not covered, because nothing here can run them: the scheduler, image pulls, the
//! volume, and building the image from the Containerfile (no container engine). The
//! manifests are validated against the Kubernetes API schemas by `kubernetes-validate`
//! (from PyPI; `.ci/run` installs it) where it is installed.

mod common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::farm::{
    MIPRAY, assert_complete_sequence, assert_records_match_reference, example, frames_arg,
    render_reference, shard_starts,
};
use common::shared_data::skip_or_fail;

/// The manifest's text.
fn manifest(name: &str) -> String {
    let path = example(&format!("kubernetes/{name}"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The value of the first `key: value` line (comments and quotes stripped).
fn scalar(text: &str, key: &str) -> String {
    text.lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(':'))
        .unwrap_or_else(|| panic!("no `{key}:` in the manifest"))
        .trim()
        .trim_matches('"')
        .to_string()
}

/// The container's `command`: the manifests keep it on one line as a flow sequence of
/// quoted strings, which is JSON.
fn command(text: &str) -> Vec<String> {
    let line = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("command:"))
        .expect("the manifest has a `command:` line");
    serde_json::from_str(line.trim()).unwrap_or_else(|e| {
        panic!("`command:{line}` is not one flow sequence of quoted strings: {e}")
    })
}

/// The container's `env` entries (`- name: N` followed by `value: "V"`).
fn env(text: &str) -> Vec<(String, String)> {
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    lines
        .windows(2)
        .filter_map(|pair| {
            let name = pair[0].strip_prefix("- name:")?.trim();
            let value = pair[1].strip_prefix("value:")?.trim().trim_matches('"');
            Some((name.to_string(), value.to_string()))
        })
        .collect()
}

/// The argument after `flag`.
fn flag_value<'a>(command: &'a [String], flag: &str) -> &'a str {
    let at = command
        .iter()
        .position(|a| a == flag)
        .unwrap_or_else(|| panic!("no {flag} in {command:?}"));
    &command[at + 1]
}

/// `command` with the test's binary, frames, size and volume folder.
fn localise(
    command: &[String],
    mount: &str,
    volume: &Path,
    replace: &[(&str, &str)],
) -> Vec<String> {
    let mut local: Vec<String> = command.to_vec();
    assert_eq!(local[0], "mipray", "the image puts mipray on PATH");
    local[0] = MIPRAY.to_string();
    for (flag, value) in replace {
        let at = local.iter().position(|a| a == flag).unwrap() + 1;
        local[at] = value.to_string();
    }
    for arg in &mut local {
        if let Some(rest) = arg.strip_prefix(mount) {
            *arg = format!("{}{rest}", volume.display());
        }
    }
    local
}

/// A container's process: a bare environment (the manifest's `env` and what Kubernetes
/// adds), started in a folder holding `animations/` like the image's working folder.
fn container(command: &[String], env: &[(String, String)], logs: &Path, name: &str) -> Child {
    let log = std::fs::File::create(logs.join(format!("{name}.log"))).unwrap();
    Command::new(&command[0])
        .args(&command[1..])
        .env_clear()
        .env("PATH", "/usr/local/bin:/usr/bin:/bin")
        .envs(env.iter().map(|(k, v)| (k, v)))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::null())
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .expect("start a container's command")
}

fn wait_success(mut child: Child, what: &str, logs: &Path) {
    let status = child.wait().unwrap();
    let log = std::fs::read_to_string(logs.join(format!("{what}.log"))).unwrap_or_default();
    assert!(status.success(), "{what} exited {status}: {log}");
}

#[test]
fn indexed_job_emulated_equals_one_machine() {
    let job = manifest("job.yaml");
    let merge_job = manifest("merge-job.yaml");
    // What the manifest must say for the shards to cover the frames once.
    assert_eq!(scalar(&job, "completionMode"), "Indexed");
    let completions = scalar(&job, "completions");
    assert_eq!(scalar(&job, "parallelism"), completions);
    let pod_env = env(&job);
    assert!(
        pod_env
            .iter()
            .any(|(k, v)| k == "MIPRAY_SHARD_COUNT" && *v == completions),
        "MIPRAY_SHARD_COUNT must equal completions ({completions}): {pod_env:?}"
    );
    let render = command(&job);
    assert!(render.iter().any(|a| a == "--resume"), "{render:?}");
    assert!(
        !render.iter().any(|a| a == "--shard"),
        "the index comes from the Job"
    );
    let merge = command(&merge_job);
    let mount = scalar(&job, "mountPath");
    assert_eq!(scalar(&merge_job, "mountPath"), mount);
    let out = flag_value(&render, "--out");
    assert!(
        out.starts_with(&format!("{mount}/")),
        "--out {out} is on the volume {mount}"
    );
    assert_eq!(merge[1..3], ["report".to_string(), out.to_string()]);
    assert_eq!(
        flag_value(&merge, "--expect-frames"),
        flag_value(&render, "--frames")
    );
    let image = scalar(&job, "image");
    assert_eq!(scalar(&merge_job, "image"), image);
    assert!(
        manifest("Containerfile").contains(&format!("-t {image} ")),
        "the Containerfile's build command tags {image}"
    );

    // The emulation: 3 pods, the test's frames and size.
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let (volume, logs) = (dir.path().join("volume"), dir.path().join("logs"));
    std::fs::create_dir_all(&logs).unwrap();
    let frames = 0..12;
    let (size, pods, killed) = ("320x180", 3u32, 1u32);
    let render = localise(
        &render,
        &mount,
        &volume,
        &[("--frames", &frames_arg(&frames)), ("--size", size)],
    );
    let pod_env: Vec<(String, String)> = pod_env
        .into_iter()
        .map(|(k, v)| match k.as_str() {
            "MIPRAY_SHARD_COUNT" => (k, pods.to_string()),
            _ => (k, v),
        })
        .collect();
    let pod = |index: u32, attempt: u32| {
        let mut env = pod_env.clone();
        env.push(("JOB_COMPLETION_INDEX".into(), index.to_string()));
        container(&render, &env, &logs, &format!("pod-{index}-{attempt}"))
    };
    let mut running: Vec<(u32, Child)> = (0..pods).map(|i| (i, pod(i, 0))).collect();
    // Pod `killed` is stopped (SIGTERM, as Kubernetes stops a pod) after its first frame;
    // the Job starts a new pod for the index.
    let out_dir = PathBuf::from(flag_value(&render, "--out"));
    let stats = out_dir.join(format!("stats.shard-{killed}-of-{pods}.jsonl"));
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::fs::read_to_string(&stats).map_or(true, |t| t.lines().count() == 0) {
        assert!(Instant::now() < deadline, "pod {killed} recorded no frame");
        std::thread::sleep(Duration::from_millis(20));
    }
    let (_, mut victim) = running.remove(killed as usize);
    // SAFETY: kill has no memory preconditions; the pid is our own unreaped child's.
    unsafe { libc::kill(victim.id() as libc::pid_t, libc::SIGTERM) };
    let status = victim.wait().unwrap();
    assert!(
        !status.success(),
        "pod {killed} finished before it was stopped: nothing left to resume"
    );
    let before: BTreeSet<u32> = records_of(&stats);
    // The new pod resumes beside the others, which are still rendering into the folder.
    running.push((killed, pod(killed, 1)));
    for (index, child) in running {
        let attempt = u32::from(index == killed);
        wait_success(child, &format!("pod-{index}-{attempt}"), &logs);
    }
    let block = records_of(&stats);
    println!(
        "pod {killed} stopped ({status}) after recording {before:?} of {block:?}; pods ran in {:.1} s",
        started.elapsed().as_secs_f64()
    );

    // The merge Job's command, then the comparison with one machine.
    let merge = localise(
        &merge,
        &mount,
        &volume,
        &[("--expect-frames", &frames_arg(&frames))],
    );
    wait_success(container(&merge, &[], &logs, "merge"), "merge", &logs);
    let reference = dir.path().join("reference");
    render_reference(&frames, size, &reference);
    // The pods rendered the scene by name from animations/; the reference by path.
    assert_complete_sequence(&reference, &out_dir, &frames);
    // Where processes started: each shard's first frame, and the first frame the stopped
    // pod had not recorded (the new pod's first).
    let mut first_frames = shard_starts(&out_dir);
    first_frames.extend(block.difference(&before).next());
    assert_records_match_reference(&reference, &out_dir, &frames, Some(&first_frames));
    println!(
        "Kubernetes emulation done in {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

fn records_of(stats: &Path) -> BTreeSet<u32> {
    std::fs::read_to_string(stats)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| mipray::record::Record::parse(l).ok())
        .filter(|r| r.missing().is_empty())
        .map(|r| r.frame())
        .collect()
}

/// Every COPY source of the Containerfile exists in the repository, so a build from its
/// root finds them (the image itself cannot be built here: no container engine).
#[test]
fn containerfile_copies_what_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = manifest("Containerfile");
    let mut sources = 0;
    for line in text.lines().filter(|l| l.starts_with("COPY ")) {
        let words: Vec<&str> = line.split_whitespace().skip(1).collect();
        if words.iter().any(|w| w.starts_with("--from")) {
            continue;
        }
        for source in &words[..words.len() - 1] {
            assert!(
                root.join(source).exists(),
                "COPY {source}: not in the repository"
            );
            sources += 1;
        }
    }
    assert!(sources >= 4, "found {sources} COPY sources");
}

/// The manifests against the Kubernetes API's schemas (unknown fields are errors).
#[test]
fn manifests_validate_against_the_kubernetes_schemas() {
    let probe = Command::new("python3")
        .args(["-m", "kubernetes_validate", "--version"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        skip_or_fail("kubernetes-validate is not installed (pip install kubernetes-validate)");
        return;
    }
    for name in ["job.yaml", "merge-job.yaml", "volume.yaml"] {
        let output = Command::new("python3")
            .args(["-m", "kubernetes_validate", "--strict"])
            .arg(example(&format!("kubernetes/{name}")))
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{name}: {}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }
}
