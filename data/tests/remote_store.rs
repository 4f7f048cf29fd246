//! Sharded stores read from object storage: over HTTP from a Python server the test starts, and from S3 as served by
//! moto's local S3 server (PyPI `moto[server]`; `.ci/run` installs it and sets ANY4D_REQUIRE_MOTO, without which a
//! machine lacking it prints "skipped"). No client is mocked: the real `object_store` clients talk to real servers.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use any4d_data::store::remote::{cache_root, fetch, is_url};
use any4d_data::store::{self, MANIFEST_FILE, ShardSpec, Store, write_synth_shard};
use any4d_data::synth::SynthConfig;

/// A child process killed when dropped.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A static file server over `root` on a free port; with `truncate`, every `clips.bin` is announced whole but
/// only half sent before the connection closes. Returns the server and its base URL.
fn http_server(root: &Path, truncate: bool) -> (Server, String) {
    let script = r#"
import functools, http.server, os, sys
root, truncate = sys.argv[1], sys.argv[2] == "1"
class Handler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass
    def do_GET(self):
        if truncate and self.path.endswith("clips.bin"):
            data = open(os.path.join(root, self.path.lstrip("/")), "rb").read()
            self.send_response(200)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data[: len(data) // 2])
            self.wfile.flush()
            self.close_connection = True
            return
        super().do_GET()
with http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=root)) as server:
    print(server.server_address[1], flush=True)
    server.serve_forever()
"#;
    let mut child = Command::new("python3")
        .args(["-c", script])
        .arg(root)
        .arg(if truncate { "1" } else { "0" })
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let port: u16 = line.trim().parse().expect("the server prints its port");
    (Server(child), format!("http://127.0.0.1:{port}"))
}

/// A sharded store of 2 shards of 12 procedural clips under `dir/store`.
fn sharded(dir: &Path) -> PathBuf {
    let root = dir.join("store");
    let cfg = SynthConfig {
        clips: 12,
        seed: 5,
        frames: 16,
        min_vertices: 256,
        max_vertices: 512,
        ..SynthConfig::default()
    };
    let dirs: Vec<PathBuf> = (0..2).map(|k| root.join(format!("shard-{k}"))).collect();
    for (k, d) in dirs.iter().enumerate() {
        write_synth_shard(&cfg, d, 8, (16, 1), Some(ShardSpec { index: k, count: 2 }), None).unwrap();
    }
    store::merge(&root, &dirs).unwrap();
    root
}

fn by_id(s: &Store) -> BTreeMap<String, Vec<u8>> {
    (0..s.len())
        .map(|i| (s.get(i).unwrap().clip.id, s.raw(i).unwrap()))
        .collect()
}

#[test]
fn a_store_served_over_http_reads_as_the_local_one_and_is_cached() {
    let tmp = tempfile::tempdir().unwrap();
    let root = sharded(tmp.path());
    let (_server, base) = http_server(tmp.path(), false);
    let url = format!("{base}/store");
    assert!(is_url(Path::new(&url)));
    let cache = tmp.path().join("cache");
    let local = fetch(&url, &[], &cache).unwrap();
    assert!(local.starts_with(&cache));
    assert_eq!(
        by_id(&Store::open(&local).unwrap()),
        by_id(&Store::open(&root).unwrap())
    );
    assert!(store::verify_store(&local).unwrap().is_ok());
    // A second fetch finds the shards cached: nothing is written again.
    let clips = local.join("shard-0/clips.bin");
    let before = std::fs::metadata(&clips).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    assert_eq!(fetch(&url, &[], &cache).unwrap(), local);
    assert_eq!(std::fs::metadata(&clips).unwrap().modified().unwrap(), before);
    // A shard re-imported and merged again on the server is fetched again.
    let more = SynthConfig {
        clips: 6,
        seed: 77,
        frames: 16,
        min_vertices: 256,
        max_vertices: 512,
        ..SynthConfig::default()
    };
    let spec = ShardSpec { index: 1, count: 2 };
    write_synth_shard(&more, &root.join("shard-1"), 8, (16, 1), Some(spec), None).unwrap();
    store::merge(&root, &[root.join("shard-0"), root.join("shard-1")]).unwrap();
    let again = fetch(&url, &[], &cache).unwrap();
    assert_eq!(
        by_id(&Store::open(&again).unwrap()),
        by_id(&Store::open(&root).unwrap())
    );
    assert_eq!(
        std::fs::metadata(&clips).unwrap().modified().unwrap(),
        before,
        "shard 0 did not change"
    );
}

#[test]
fn unreachable_truncated_and_changed_remote_shards_are_named_and_leave_no_store() {
    let tmp = tempfile::tempdir().unwrap();
    sharded(tmp.path());
    let cache = tmp.path().join("cache");
    let no_store = |dir: &Path| !dir.join(MANIFEST_FILE).exists() && !dir.join("shard-0/clips.bin").exists();
    // Nothing listens on port 1.
    let e = fetch("http://127.0.0.1:1/store", &[], &cache).unwrap_err().to_string();
    assert!(
        e.contains("http://127.0.0.1:1/store") && e.contains("cannot be read"),
        "{e}"
    );
    // A server that closes the connection halfway through every clips.bin.
    let (server, base) = http_server(tmp.path(), true);
    let url = format!("{base}/store");
    let e = fetch(&url, &[], &cache).unwrap_err().to_string();
    assert!(e.contains("shards[0]") && e.contains("clips.bin"), "{e}");
    let dirs: Vec<PathBuf> = std::fs::read_dir(&cache).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(dirs.len(), 1);
    assert!(no_store(&dirs[0]), "a half transfer was left as if complete");
    let leftovers: Vec<_> = std::fs::read_dir(dirs[0].join("shard-0")).unwrap().collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    drop(server);
    // A manifest whose checksum is not the shard's.
    let root = tmp.path().join("store");
    let text = std::fs::read_to_string(root.join(MANIFEST_FILE)).unwrap();
    let manifest: store::Manifest = serde_json::from_str(&text).unwrap();
    let wrong = text.replace(&manifest.shards[1].checksum, "0123456789abcdef");
    std::fs::write(root.join(MANIFEST_FILE), wrong).unwrap();
    let (_server, base) = http_server(tmp.path(), false);
    let e = fetch(&format!("{base}/store"), &[], &cache).unwrap_err().to_string();
    assert!(e.contains("shards[1]") && e.contains("checksum"), "{e}");
    for dir in std::fs::read_dir(&cache).unwrap() {
        assert!(
            !dir.unwrap().path().join(MANIFEST_FILE).exists(),
            "a store was left in the cache"
        );
    }
    // Shards outside the store cannot be named by a remote manifest.
    std::fs::write(root.join(MANIFEST_FILE), text.replace("\"shard-1\"", "\"../shard-1\"")).unwrap();
    let e = fetch(&format!("{base}/store"), &[], &cache).unwrap_err().to_string();
    assert!(e.contains("inside it"), "{e}");
    // Not a store at all.
    let e = fetch(&format!("{base}/nothing"), &[], &cache).unwrap_err().to_string();
    assert!(e.contains(MANIFEST_FILE) && e.contains("data merge"), "{e}");
    // Stores are written locally, never to a URL.
    let e = store::import(
        &[tmp.path().join("store")],
        Path::new("s3://bucket/new"),
        &Default::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("upload_store.py"), "{e}");
    let e = store::merge(Path::new("s3://bucket/new"), &[root.join("shard-0")])
        .unwrap_err()
        .to_string();
    assert!(e.contains("upload_store.py"), "{e}");
    assert!(!Path::new("s3:").exists());
    assert!(cache_root().is_ok());
}

/// A free TCP port on the loopback.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn a_store_in_s3_is_read_through_the_s3_client() {
    let required = std::env::var_os("ANY4D_REQUIRE_MOTO").is_some();
    let found = Command::new("moto_server")
        .arg("--help")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    if !found.is_ok_and(|s| s.success()) {
        assert!(
            !required,
            "ANY4D_REQUIRE_MOTO is set but moto_server does not run (pip install 'moto[server]')"
        );
        println!("skipped: moto_server not found (pip install 'moto[server]')");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let root = sharded(tmp.path());
    let port = free_port();
    let _server = Server(
        Command::new("moto_server")
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let endpoint = format!("http://127.0.0.1:{port}");
    // The bucket and its objects, written by boto3 (moto's own dependency), once the server answers.
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/upload_store.py");
    let status = Command::new("python3")
        .arg(script)
        .args([&endpoint, "clips", "corpus"])
        .arg(&root)
        .envs([
            ("AWS_ACCESS_KEY_ID", "test"),
            ("AWS_SECRET_ACCESS_KEY", "test"),
            ("AWS_DEFAULT_REGION", "us-east-1"),
        ])
        .status()
        .unwrap();
    assert!(status.success(), "uploading to moto");
    let options: Vec<(String, String)> = [
        ("aws_endpoint", endpoint.as_str()),
        ("aws_allow_http", "true"),
        ("aws_access_key_id", "test"),
        ("aws_secret_access_key", "test"),
        ("aws_region", "us-east-1"),
    ]
    .iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect();
    let cache = tmp.path().join("cache");
    let local = fetch("s3://clips/corpus", &options, &cache).unwrap();
    assert_eq!(
        by_id(&Store::open(&local).unwrap()),
        by_id(&Store::open(&root).unwrap())
    );
    let e = fetch("s3://no-such-bucket/corpus", &options, &cache)
        .unwrap_err()
        .to_string();
    assert!(e.contains("s3://no-such-bucket/corpus"), "{e}");
}
