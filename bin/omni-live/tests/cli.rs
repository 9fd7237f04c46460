//! omni-live as a user runs it: no output (sweep lines only), bad files and options refused in
//! one line before the network is touched, a closed stdout and SIGTERM are clean ends.

use std::io::Write;
use std::process::{Child, Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_omni-live");

fn stream(sweeps: u64) -> String {
    let mut s =
        String::from("{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1,\"angles\":\"0:3:1\"}\n");
    for seq in 0..3 * sweeps {
        s += &format!(
            "{{\"type\":\"frame\",\"seq\":{seq},\"path\":\"{seq}.png\",\"alpha_deg\":{},\"facet\":{},\"lasers\":[0],\
             \"timestamp_us\":{},\"stripe\":[[1,2,80,2,0]],\"points\":[[100,0,{seq},0,100,0]]}}\n",
            seq % 3,
            seq / 3,
            1000 * seq
        );
    }
    s + &format!(
        "{{\"type\":\"status\",\"frames\":{},\"frames_missing\":0,\"complete\":true,\"errors\":[]}}\n",
        3 * sweeps
    )
}

/// The tool with all three standard streams piped.
fn spawn(args: &[&str]) -> Child {
    Command::new(BIN).args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
}

fn run(args: &[&str], input: &str) -> Output {
    let mut child = spawn(args);
    let mut stdin = child.stdin.take().unwrap();
    let _ = stdin.write_all(input.as_bytes());
    drop(stdin);
    child.wait_with_output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn without_an_output_it_reports_each_sweep_and_a_status() {
    let o = run(&[], &stream(4));
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> =
        String::from_utf8_lossy(&o.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 1, "no sinks: only the status line");
    assert!(stderr(&o).contains("neither --ros2 nor --foxglove: nothing is published"), "{}", stderr(&o));
    assert_eq!(lines[0]["sweeps"], 4);
    assert_eq!(lines[0]["frames"], 12);
    assert_eq!(lines[0]["sweeps_incomplete"], 0);
}

#[test]
fn bad_files_and_options_are_refused_in_one_line_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path.display().to_string()
    };
    let skewed = p(
        "skew.json",
        r#"{"format":"omniscan.transform","version":1,"rotation":[[1,0.1,0],[0,1,0],[0,0,1]],"translation_mm":[0,0,0]}"#,
    );
    let nan = p(
        "nan.json",
        r#"{"format":"omniscan.transform","version":1,"rotation":[[1,0,0],[0,1,0],[0,0,1]],"translation_mm":[0,NaN,0]}"#,
    );
    let v9 = p(
        "v9.json",
        r#"{"format":"omniscan.transform","version":9,"rotation":[[1,0,0],[0,1,0],[0,0,1]],"translation_mm":[0,0,0]}"#,
    );
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (vec!["--ros2", "--extrinsics", &skewed], vec!["skew.json", "rotation", "not a rotation matrix"]),
        (vec!["--ros2", "--extrinsics", &nan], vec!["nan.json"]),
        (vec!["--ros2", "--extrinsics", &v9], vec!["v9.json", "version 9"]),
        (vec!["--ros2", "--domain-id", "300"], vec!["--domain-id 300", "0..=232"]),
        (vec!["--ros2", "--prefix", "omniscan"], vec!["prefix", "must start with /"]),
        (vec!["--ros2", "--camera", "/no/such/camera.json"], vec!["/no/such/camera.json"]),
    ];
    for (args, words) in cases {
        let o = run(&args, "");
        let e = stderr(&o);
        let usage = args.contains(&"--domain-id");
        assert_eq!(o.status.code(), Some(if usage { 2 } else { 1 }), "{args:?}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{e}");
        for w in words {
            assert!(e.contains(w), "{args:?}: {e:?} lacks {w:?}");
        }
    }
}

#[test]
fn a_malformed_record_is_named_by_its_line() {
    let mut s = stream(1);
    s.insert_str(s.find("{\"type\":\"frame\"").unwrap(), "{\"type\":\"frame\",\"seq\":\"x\"}\n");
    let o = run(&[], &s);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("stdin") && e.contains("line 2"), "{e}");
}

#[test]
fn a_stream_not_yet_triangulated_is_refused_naming_its_first_frame() {
    let s = stream(1).replace(",\"points\":[[100,0,1,0,100,0]]", "");
    let o = run(&[], &s);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("stdin: line 3 (frame 1): no `points` field (run omni-triangulate first)"), "{e}");
    assert_eq!(e.lines().filter(|l| l.contains("error")).count(), 1, "{e}");
}

#[test]
fn a_closed_stdout_is_a_clean_end() {
    let mut child = spawn(&["--frames-per-sweep", "1"]);
    drop(child.stdout.take());
    let _ = child.stdin.take().unwrap().write_all(stream(50).as_bytes());
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

#[test]
fn sigterm_publishes_the_open_sweep_and_ends_with_the_status() {
    let mut child = spawn(&["--sweep-timeout-ms", "60000"]);
    let mut stdin = child.stdin.take().unwrap();
    // Two frames of a three-frame sweep; the input stays open.
    let s = stream(1);
    let partial: String = s.lines().take(3).map(|l| format!("{l}\n")).collect();
    stdin.write_all(partial.as_bytes()).unwrap();
    stdin.flush().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(Command::new("kill").arg("-TERM").arg(child.id().to_string()).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    drop(stdin);
    assert!(o.status.success(), "{}", stderr(&o));
    let last: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&o.stdout).lines().last().unwrap()).unwrap();
    assert_eq!(
        (last["type"].as_str(), last["sweeps"].as_u64(), last["sweeps_incomplete"].as_u64()),
        (Some("status"), Some(1), Some(1))
    );
}

#[test]
fn a_foxglove_port_in_use_is_a_one_line_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let o = run(&["--foxglove", &format!("127.0.0.1:{port}")], "");
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains(&format!("--foxglove 127.0.0.1:{port}")), "{e}");
    let o = run(&["--foxglove", "localhost:http"], "");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn an_empty_input_is_an_error() {
    let o = run(&[], "");
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("stdin: empty stream"), "{}", stderr(&o));
    // A malformed line, and frames without their header, are named once with their line.
    let header = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n";
    let frame = "{\"type\":\"frame\",\"seq\":0,\"path\":\"a.png\",\"alpha_deg\":0,\"facet\":0}\n";
    for (input, expected) in [
        (format!("{header}{{\"type\":"), "stdin: line 2: invalid JSON"),
        (frame.to_string(), "stdin: line 1: the stream starts"),
    ] {
        let o = run(&[], &input);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(e.contains(expected) && e.matches("stdin").count() == 1, "{e}");
    }
}
