//! Sharded stores from the command line, as a cluster would drive them: `data synth --shard K/N` run as separate
//! processes, `data merge`, the merged store inspected, verified and rendered, the same store read over HTTP, the
//! streaming reader's benchmark (`bench store`) on it, and refused `--shard` values.

use std::path::Path;

mod common;
use common::{any4d, text};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn shards_written_by_two_processes_merge_into_one_store() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let synth = |shard: &str, out: &Path| {
        let args = [
            "data", "synth", "--clips", "6", "--seed", "5", "--p", "16", "--shard", shard, "--out",
        ];
        std::process::Command::new(env!("CARGO_BIN_EXE_any4d"))
            .args(args)
            .arg(out)
            .spawn()
            .unwrap()
    };
    // Two processes at once, as an array job would run them.
    let (a, b) = (store.join("shard-0"), store.join("shard-1"));
    let children = [synth("0/2", &a), synth("1/2", &b)];
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
    let out = any4d(&["data", "merge", p(&store), p(&a), p(&b)]);
    let (stdout, stderr) = text(&out);
    assert!(
        out.status.success() && stdout.contains("2 shards, 6 clips"),
        "{stdout}{stderr}"
    );
    let out = any4d(&["data", "inspect", p(&store)]);
    let (stdout, _) = text(&out);
    assert!(
        out.status.success() && stdout.contains("6 ok") && stdout.contains("shard-1"),
        "{stdout}"
    );
    let out = any4d(&["data", "verify", p(&store)]);
    let (stdout, _) = text(&out);
    assert!(out.status.success() && stdout.contains("2 shards match"), "{stdout}");
    let out = any4d(&["data", "render", p(&store), "--out", p(&tmp.path().join("s.png"))]);
    assert!(out.status.success(), "{:?}", text(&out));
    // The same store over HTTP, as a URL in place of the folder, cached where ANY4D_CACHE says.
    let mut server = std::process::Command::new("python3")
        .args(["-u", "-m", "http.server", "0", "--bind", "127.0.0.1", "--directory"])
        .arg(tmp.path())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(server.stdout.take().unwrap()), &mut line).unwrap();
    let port = line
        .split(" port ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap()
        .to_owned();
    let url = format!("http://127.0.0.1:{port}/store");
    for cmd in ["inspect", "verify"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_any4d"))
            .args(["data", cmd, &url])
            .env("ANY4D_CACHE", tmp.path().join("cache"))
            .output()
            .unwrap();
        let (stdout, stderr) = text(&out);
        assert!(out.status.success() && stdout.contains("6 "), "{cmd}: {stdout}{stderr}");
    }
    // The streaming reader's benchmark: the same clips as one file, as two shards, and over HTTP (cold, cached).
    let one = tmp.path().join("one");
    let out = any4d(&[
        "data",
        "synth",
        "--clips",
        "6",
        "--seed",
        "5",
        "--p",
        "16",
        "--out",
        p(&one),
    ]);
    assert!(out.status.success(), "{:?}", text(&out));
    let csv = tmp.path().join("bench.csv");
    let out = any4d(&[
        "bench",
        "store",
        p(&one),
        p(&store),
        &url,
        "--rounds",
        "2",
        "--csv",
        p(&csv),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success() && stdout.contains("clips/s"), "{stdout}{stderr}");
    let rows: Vec<Vec<String>> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.rsplitn(8, ',').map(str::to_owned).collect())
        .collect();
    // Columns from the right: ratio, MB/s, clips/s, seconds, bytes, clips, shards, store.
    let shards: Vec<&str> = rows.iter().map(|r| r[6].as_str()).collect();
    assert_eq!(shards, ["1", "2", "2", "2"], "{rows:?}");
    assert!(rows.iter().all(|r| r[5] == "6"), "{rows:?}");
    assert_eq!(rows[0][0], "1.0000");
    assert!(
        rows[2][7].contains("empty cache") && rows[3][7].contains("cache filled"),
        "{rows:?}"
    );
    let out = any4d(&["bench", "store", p(&one), "--rounds", "0"]);
    assert!(
        !out.status.success() && text(&out).1.contains("--rounds"),
        "{:?}",
        text(&out)
    );
    let _ = server.kill();
    let _ = server.wait();
    for bad in ["3/2", "0/0", "1"] {
        let out = any4d(&[
            "data",
            "synth",
            "--clips",
            "2",
            "--seed",
            "5",
            "--shard",
            bad,
            "--out",
            p(&tmp.path().join("x")),
        ]);
        let (_, stderr) = text(&out);
        assert!(
            !out.status.success() && stderr.contains("--shard") && stderr.contains(bad),
            "{bad}: {stderr}"
        );
        assert!(!tmp.path().join("x").exists());
    }
}
