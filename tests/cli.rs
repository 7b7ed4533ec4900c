//! The binary's contract: renders and reports, and bad input exits non-zero with an error
//! that names the file, never a panic.

use std::path::Path;
use std::process::{Command, Output};

mod common;

use common::mipray;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A one-triangle glTF with an external texture `tex.png`, written into `dir`.
fn write_textured_triangle(dir: &Path, with_texture: bool) -> std::path::PathBuf {
    use base64::Engine;
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.0f32, 0.0, 1.0, 0.0, 0.0, 1.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    let json = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"uri": "tex.png"}],
        "buffers": [{"byteLength": bin.len(), "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 24}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}
        ]
    });
    if with_texture {
        image::RgbImage::from_fn(4, 4, |x, y| {
            image::Rgb([(x * 60) as u8, (y * 60) as u8, 128])
        })
        .save(dir.join("tex.png"))
        .unwrap();
    }
    let path = dir.join("tri.gltf");
    std::fs::write(&path, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    path
}

#[test]
fn renders_a_scene_and_writes_frames_and_stats() {
    let dir = tempfile::tempdir().unwrap();
    write_textured_triangle(dir.path(), true);
    let out = mipray(
        &[
            "render", "tri.gltf", "--size", "32x24", "--frames", "0..2", "--out", "o",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    for f in [
        "o/frame_0000.png",
        "o/frame_0001.png",
        "o/stats.jsonl",
        "o/summary.json",
    ] {
        assert!(dir.path().join(f).is_file(), "missing {f}");
    }
    let stats = std::fs::read_to_string(dir.path().join("o/stats.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = stats
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    for key in [
        "frame",
        "time_s",
        "width",
        "height",
        "lod_method",
        "triangles",
        "build_ms",
        "render_ms",
        "rays",
        "mip_histogram",
    ] {
        assert!(lines[0].get(key).is_some(), "stats line lacks {key}");
    }
    assert_eq!(lines[1]["frame"], 1);
    assert_eq!(lines[0]["triangles"], 1);
    assert!(lines[0]["rays"].as_u64().unwrap() >= 32 * 24);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("o"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left behind");
}

#[test]
fn info_reports_counts() {
    let dir = tempfile::tempdir().unwrap();
    write_textured_triangle(dir.path(), true);
    let out = mipray(&["info", "tri.gltf"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(
            "triangles: 1 (1 static, 0 moved by animated nodes, 0 skinned or morphing)\n"
        ),
        "{text}"
    );
    assert!(text.contains("4x4, 3 MIP levels"), "{text}");
    assert!(text.contains("MIP filter linear"), "{text}");
}

#[test]
fn missing_texture_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    write_textured_triangle(dir.path(), false);
    let out = mipray(
        &["render", "tri.gltf", "--size", "8x8", "--out", "o"],
        dir.path(),
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("tri.gltf") && err.contains("tex.png"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn truncated_file_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_textured_triangle(dir.path(), true);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    for command in ["render", "info"] {
        let out = mipray(&[command, "tri.gltf"], dir.path());
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{command}: {err}");
        assert!(err.contains("tri.gltf"), "{command}: {err}");
        assert!(!err.contains("panicked"), "{command}: {err}");
    }
}

#[test]
fn bad_options_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_textured_triangle(dir.path(), true);
    // A flag value out of its range is a usage error (status 2, as the parser's own); a
    // scene that does not exist is an error of the run (status 1).
    for args in [
        &["render", "tri.gltf", "--size", "0x5"][..],
        &["render", "tri.gltf", "--size", "12xa"],
        &["render", "tri.gltf", "--frames", "5..2"],
        &["render", "tri.gltf", "--spp", "0"],
        &["render", "tri.gltf", "--lod", "bogus"],
        &["render", "tri.gltf", "--lod-bias", "99"],
        &["render", "tri.gltf", "--mip-filter", "cubic"],
        &["render", "tri.gltf", "--shard", "4/4"],
        &["render", "tri.gltf", "--shard", "x"],
        // Frame 1 of 2 at 1e-45 frames a second would be at an infinite time.
        &["render", "tri.gltf", "--fps", "1e-45", "--frames", "0..2"],
        &["compare", "tri.gltf", "--repeats", "0"],
        &["man", "rendr"],
        // Worker counts the system would take minutes to start are refused up front.
        &["render", "tri.gltf", "--threads", "0"],
        &["render", "tri.gltf", "--threads", "100000"],
        &["bench", "tri.gltf", "--threads", "1,100000"],
        &[
            "bench",
            "tri.gltf",
            "--rays",
            "primary",
            "--min-sample-ms",
            "nan",
        ],
        &[
            "bench",
            "tri.gltf",
            "--rays",
            "primary",
            "--min-sample-ms",
            "1e9",
        ],
        &["render", "no-such-scene"],
    ] {
        let out = mipray(args, dir.path());
        let usage = args[1] != "no-such-scene";
        assert_eq!(
            out.status.code(),
            Some(if usage { 2 } else { 1 }),
            "{args:?}: {}",
            stderr(&out)
        );
        assert!(
            !stderr(&out).contains("panicked"),
            "{args:?}: {}",
            stderr(&out)
        );
        if args.contains(&"--min-sample-ms") {
            assert!(
                stderr(&out).contains("--min-sample-ms") && stderr(&out).contains("0 to 60000"),
                "{}",
                stderr(&out)
            );
        }
        if args.contains(&"--threads") {
            assert!(
                stderr(&out).contains("must be 1 to 1024"),
                "{}",
                stderr(&out)
            );
        }
    }
    // So is a worker count given through rayon's own variable.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(["render", "tri.gltf"])
        .current_dir(dir.path())
        .env("RAYON_NUM_THREADS", "99999")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("RAYON_NUM_THREADS=99999: at most 1024"),
        "{}",
        stderr(&out)
    );
    // A copy of the hot loops that does not exist is refused, not silently replaced by the
    // default one (a comparison would measure the wrong copy).
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(["info", "tri.gltf"])
        .current_dir(dir.path())
        .env("MIPRAY_SIMD", "avx-512")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("MIPRAY_SIMD=avx-512: expected auto, baseline or avx2"),
        "{}",
        stderr(&out)
    );
    // A folder given as the scene, a file given as the output folder: said in words.
    std::fs::create_dir(dir.path().join("folder.gltf")).unwrap();
    let out = mipray(&["render", "folder.gltf"], dir.path());
    assert!(
        stderr(&out).contains("folder.gltf: is a folder"),
        "{}",
        stderr(&out)
    );
    std::fs::write(dir.path().join("taken"), "").unwrap();
    let out = mipray(&["render", "tri.gltf", "--out", "taken"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("taken: exists and is not a folder"),
        "{}",
        stderr(&out)
    );
    // `compare` says so before its renders (which take minutes on a real scene), not after.
    let out = mipray(
        &["compare", "tri.gltf", "--size", "8x8", "--out", "taken"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("taken: exists and is not a folder"), "{err}");
    assert!(
        !err.lines().any(|l| l.starts_with("compare: ")),
        "refused only after starting the renders: {err}"
    );
}

#[test]
fn default_animation_renders_by_name_identically_with_one_or_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let common = [
        "render", "default", "--size", "96x54", "--frames", "10..12", "--spp", "2",
    ];
    for threads in ["1", "2"] {
        let out_dir = format!("t{threads}");
        let mut args = common.to_vec();
        args.extend(["--threads", threads, "--out", &out_dir]);
        let out = mipray(&args, dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
    }
    for frame in ["frame_0010.png", "frame_0011.png"] {
        let a = std::fs::read(dir.path().join("t1").join(frame)).unwrap();
        let b = std::fs::read(dir.path().join("t2").join(frame)).unwrap();
        assert!(a == b, "{frame} differs between 1 and 2 threads");
    }
    // Frame 11 rendered alone is the same file as frame 11 of the sequence.
    let out = mipray(
        &[
            "render", "default", "--size", "96x54", "--frames", "11", "--spp", "2", "--out",
            "alone",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let alone = std::fs::read(dir.path().join("alone/frame_0011.png")).unwrap();
    assert!(
        alone == std::fs::read(dir.path().join("t1/frame_0011.png")).unwrap(),
        "frame 11 alone differs"
    );
}

/// `--mip-filter nearest` reads one level a lookup: the textured frame changes, the
/// record says so, and `linear` is what the default scene's textures do already.
#[test]
fn mip_filter_flag_is_applied_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    for (out_dir, filter) in [
        ("own", None),
        ("linear", Some("linear")),
        ("nearest", Some("nearest")),
    ] {
        let mut args = vec![
            "render", "default", "--size", "96x54", "--frames", "10", "--out", out_dir,
        ];
        if let Some(filter) = filter {
            args.extend(["--mip-filter", filter]);
        }
        let out = mipray(&args, dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let frame = |d: &str| std::fs::read(dir.path().join(d).join("frame_0010.png")).unwrap();
    assert!(
        frame("own") == frame("linear"),
        "the default scene's textures are trilinear"
    );
    assert!(
        frame("own") != frame("nearest"),
        "one level a lookup changes the frame"
    );
    let record = |d: &str| std::fs::read_to_string(dir.path().join(d).join("stats.jsonl")).unwrap();
    assert!(
        record("nearest").contains(r#""mip-filter":"nearest""#),
        "{}",
        record("nearest")
    );
    assert!(
        record("own").contains(r#""mip-filter":"each texture's own""#),
        "{}",
        record("own")
    );
}

/// `mipray ARGS` in `cwd` with `MIPRAY_LARGE_PAGES` set to `setting`, or unset.
fn mipray_with_large_pages(args: &[&str], cwd: &Path, setting: Option<&str>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_mipray"));
    command.args(args).current_dir(cwd);
    match setting {
        Some(value) => command.env("MIPRAY_LARGE_PAGES", value),
        None => command.env_remove("MIPRAY_LARGE_PAGES"),
    };
    command.output().expect("run mipray")
}

/// The large-page allocator changes where memory comes from, never what is computed: a
/// frame is the same file with it off, and `bench` says which way the memory was paged.
#[test]
fn large_pages_on_or_off_render_the_same_frame() {
    let dir = tempfile::tempdir().unwrap();
    // 640x360: the frame's linear pixels (3.5 MiB) alone are a large allocation.
    let size = ["--size", "640x360"];
    for (out_dir, setting) in [("on", None), ("off", Some("off"))] {
        let args = [
            &["render", "default", "--frames", "3", "--out", out_dir][..],
            &size,
        ]
        .concat();
        let out = mipray_with_large_pages(&args, dir.path(), setting);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let frame = |d: &str| std::fs::read(dir.path().join(d).join("frame_0003.png")).unwrap();
    assert!(
        frame("on") == frame("off"),
        "the frame differs with large pages off"
    );
    // A value other than `on` and `off` is refused, naming the variable.
    let out = mipray_with_large_pages(&["info", "default"], dir.path(), Some("maybe"));
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("MIPRAY_LARGE_PAGES=maybe"),
        "{}",
        stderr(&out)
    );
    let bench = [
        "bench",
        "default",
        "--frames",
        "3..4",
        "--repeats",
        "1",
        "--methods",
        "none",
        "--threads",
        "1",
    ];
    for (setting, says) in [
        (None, "2 MiB-aligned mappings of their own"),
        (Some("off"), "from the system allocator"),
    ] {
        let out = mipray_with_large_pages(&[&bench[..], &size].concat(), dir.path(), setting);
        assert!(out.status.success(), "{}", stderr(&out));
        let note = stderr(&out);
        let line = note
            .lines()
            .find(|l| l.starts_with("memory: "))
            .unwrap_or("");
        assert!(line.contains(says), "{setting:?}: {note}");
        assert!(line.contains("MiB in reserved huge pages") || line.contains("not reported"));
    }
}

#[test]
fn exr_frames_hold_linear_floats() {
    let dir = tempfile::tempdir().unwrap();
    write_textured_triangle(dir.path(), true);
    let out = mipray(
        &[
            "render", "tri.gltf", "--size", "16x12", "--format", "exr", "--out", "e",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let image = image::open(dir.path().join("e/frame_0000.exr"))
        .expect("readable EXR")
        .to_rgb32f();
    assert_eq!(image.dimensions(), (16, 12));
    assert!(
        image
            .pixels()
            .all(|p| p.0.iter().all(|c| c.is_finite() && *c >= 0.0))
    );
    // Linear, not sRGB-encoded: the dark background (0.05 linear) stays below 0.1.
    let corner = image.get_pixel(0, 0).0;
    assert!(corner[0] < 0.1 && corner[0] > 0.0, "{corner:?}");
}

#[test]
fn interrupted_render_resumes_without_damaged_frames() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "render",
        "default",
        "--size",
        "128x72",
        "--spp",
        "4",
        "--frames",
        "0..60",
        "--threads",
        "1",
    ];
    let reference = {
        let mut a = args.to_vec();
        a.extend(["--out", "reference"]);
        let out = mipray(&a, dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
        dir.path().join("reference")
    };
    // Start the same render and kill it once a few frames are on disk.
    let mut child = Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(args)
        .args(["--out", "run"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let run = dir.path().join("run");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !run.join("frame_0003.png").exists() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        run.join("frame_0003.png").exists(),
        "the render never got going"
    );
    assert!(
        !run.join("frame_0059.png").exists(),
        "the render finished before it could be interrupted"
    );
    // Whatever the kill left, tear the stats file's last line too, as a crash mid-write would.
    let stats = run.join("stats.jsonl");
    let text = std::fs::read_to_string(&stats).unwrap();
    std::fs::write(&stats, &text[..text.len().saturating_sub(7)]).unwrap();

    let mut a = args.to_vec();
    a.extend(["--out", "run", "--resume"]);
    let out = mipray(&a, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    for frame in 0..60 {
        let name = format!("frame_{frame:04}.png");
        let got = std::fs::read(run.join(&name))
            .unwrap_or_else(|_| panic!("{name} missing after resume"));
        let want = std::fs::read(reference.join(&name)).unwrap();
        assert!(got == want, "{name} differs from an uninterrupted render");
    }
    let records: Vec<serde_json::Value> = std::fs::read_to_string(&stats)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("every stats line is complete"))
        .collect();
    let mut frames: Vec<u64> = records
        .iter()
        .map(|r| r["frame"].as_u64().unwrap())
        .collect();
    frames.sort();
    assert_eq!(
        frames,
        (0..60).collect::<Vec<u64>>(),
        "one record per frame"
    );
    let leftovers = std::fs::read_dir(&run)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .count();
    assert_eq!(leftovers, 0);
}

#[test]
fn shards_render_disjoint_blocks_that_report_merges() {
    let dir = tempfile::tempdir().unwrap();
    for shard in ["0/3", "1/3", "2/3"] {
        let out = mipray(
            &[
                "render", "default", "--size", "32x18", "--frames", "0..10", "--shard", shard,
                "--out", "s",
            ],
            dir.path(),
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let frames = std::fs::read_dir(dir.path().join("s"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("frame_"))
        .count();
    assert_eq!(frames, 10);
    let out = mipray(&["report", "s"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("frames: 10 (0 to 9, 0 missing)"), "{text}");
    assert!(text.contains("shards merged: 3"), "{text}");
    assert!(dir.path().join("s/report.svg").is_file());
}

#[test]
fn aff_scene_renders_at_its_own_frame_times() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/aff/scene.aff");
    let scene = scene.to_str().unwrap();
    let out = mipray(
        &["render", scene, "--size", "32x24", "--out", "o"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stats = std::fs::read_to_string(dir.path().join("o/stats.jsonl")).unwrap();
    let times: Vec<f64> = stats
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["time_s"]
                .as_f64()
                .unwrap()
        })
        .collect();
    // The fixture's `a 0 2 5`: five frames from 0 to 2 s.
    assert_eq!(times, vec![0.0, 0.5, 1.0, 1.5, 2.0]);
    let info = mipray(&["info", scene], dir.path());
    assert!(info.status.success(), "{}", stderr(&info));
    assert!(String::from_utf8_lossy(&info.stdout).contains("skinned or morphing"));
}

/// The AVX2 copy (chosen where the CPU has AVX2 and its integer extensions: the tile loop with its surfaces, shading
/// and texture lookups, and the walks) and the x86-64 baseline copy (`MIPRAY_SIMD=baseline`)
/// render byte-identical frames, under both BVH layouts: our kitchen has glass, mirrors and
/// textures, so closest-hit, shadow and packet walks and trilinear lookups all run.
#[test]
fn the_avx2_and_baseline_walks_render_identical_frames() {
    let dir = tempfile::tempdir().unwrap();
    for bvh in ["flat", "two-level"] {
        let mut frames = Vec::new();
        for simd in ["baseline", "auto"] {
            let out_dir = format!("{bvh}-{simd}");
            let out = Command::new(env!("CARGO_BIN_EXE_mipray"))
                .args([
                    "render", "kitchen", "--size", "96x54", "--frames", "20..23", "--lod", "paper",
                    "--bvh", bvh, "--out", &out_dir,
                ])
                .env("MIPRAY_SIMD", simd)
                .current_dir(dir.path())
                .output()
                .expect("run mipray");
            assert!(out.status.success(), "{}", stderr(&out));
            frames.push(
                ["frame_0020.png", "frame_0021.png", "frame_0022.png"]
                    .map(|f| std::fs::read(dir.path().join(&out_dir).join(f)).unwrap()),
            );
        }
        for (i, (a, b)) in frames[0].iter().zip(&frames[1]).enumerate() {
            assert!(a == b, "{bvh}: frame {} differs between the walks", 20 + i);
        }
    }
}

/// Samples whose shading overflows single precision (here two lights of 3.4e38 on one
/// triangle) are written black, counted in the record, and named in a note on stderr: the
/// render succeeds, the frame is whole, and the user is told which frame lost samples.
#[test]
fn samples_that_overflow_are_written_black_and_noted() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("bright.aff");
    std::fs::write(
        &scene,
        "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.1\nresolution 32 24\n\
         l 0 3 3 3.4e38 3.4e38 3.4e38\nl 0 3 2 3.4e38 3.4e38 3.4e38\n\
         fm 0.1 0.1 0.1  0.7 0.7 0.7  0.5 0.5 0.5  20 0 1\np 3\n-1 -1 0\n1 -1 0\n0 1 0\n",
    )
    .unwrap();
    let out = mipray(
        &[
            "render",
            scene.to_str().unwrap(),
            "--size",
            "32x24",
            "--out",
            "o",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stats = std::fs::read_to_string(dir.path().join("o/stats.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(stats.lines().next().unwrap()).unwrap();
    let lost = first["nonfinite_samples"].as_u64().unwrap();
    assert!(lost > 0, "the premise: some samples overflow ({stats})");
    let note = format!("note: frame 0000: {lost} sample(s) came out infinite or NaN");
    assert!(stderr(&out).contains(&note), "{}", stderr(&out));
    assert!(dir.path().join("o/frame_0000.png").exists());
}

/// A scene whose first frame is fine and whose animation carries a vertex out of single
/// precision's range between two finite keys (3e38 to -3e38): the render and the export
/// stop at that frame with one error naming the scene file and the frame, and the frames
/// before it stay written.
#[test]
fn a_frame_the_animation_breaks_is_an_error_naming_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/frame_errors/translation_keys_overflow_between.gltf");
    let scene = scene.to_str().unwrap();
    for command in ["render", "export"] {
        let out = mipray(
            &[
                command, scene, "--frames", "0..3", "--size", "16x12", "--out", command,
            ],
            dir.path(),
        );
        let stderr = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{command}: {stderr}");
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(errors.len(), 1, "{command}: {stderr}");
        assert!(
            errors[0].contains("translation_keys_overflow_between.gltf: frame 1 ")
                && errors[0].contains("non-finite vertex"),
            "{command}: {stderr}"
        );
    }
    assert!(dir.path().join("render/frame_0000.png").exists());
    assert!(!dir.path().join("render/frame_0001.png").exists());
}
