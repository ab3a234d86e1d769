//! Headless Chromium for the browser tests: found on PATH (or
//! FILTERJIT_CHROMIUM), its WebGPU on SwiftShader, driven through the
//! DevTools protocol; pages served over HTTP on the loopback by Python's
//! `http.server` (a secure context, where `navigator.gpu` exists).

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

/// The Chromium to test with, or `None` after saying SKIPPED loudly; in CI
/// (CI, or FILTERJIT_REQUIRE_CHROMIUM: `.ci/run` installs it) a missing one fails `test`.
pub fn chromium(test: &str) -> Option<PathBuf> {
    let found = std::env::var_os("FILTERJIT_CHROMIUM").map(PathBuf::from).or_else(|| {
        ["chromium", "chromium-browser", "google-chrome"].iter().find_map(|name| {
            std::env::var_os("PATH")?.to_str()?.split(':').map(|d| Path::new(d).join(name)).find(|p| p.is_file())
        })
    });
    if found.is_none() {
        assert!(
            std::env::var_os("FILTERJIT_REQUIRE_CHROMIUM").is_none() && std::env::var_os("CI").is_none(),
            "{test}: Chromium is required here (CI, FILTERJIT_REQUIRE_CHROMIUM) and not found"
        );
        eprintln!("\n*** SKIPPED {test}: no chromium on PATH (apt-get install chromium) ***\n");
    }
    found
}

/// A folder served over HTTP on 127.0.0.1 for as long as this lives.
pub struct Served {
    server: Child,
    pub url: String,
}

impl Served {
    pub fn folder(dir: &Path) -> Served {
        let mut server = Command::new("python3")
            .args(["-u", "-m", "http.server", "0", "--bind", "127.0.0.1", "--directory"])
            .arg(dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("python3 serves the test page (http.server)");
        // "Serving HTTP on 127.0.0.1 port 41234 (http://127.0.0.1:41234/) ..."
        let mut line = String::new();
        BufReader::new(server.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let port = line.split(" port ").nth(1).and_then(|r| r.split_whitespace().next()).unwrap_or_else(|| {
            panic!("http.server did not say its port: {line:?}");
        });
        Served { server, url: format!("http://127.0.0.1:{port}/") }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

/// One headless Chromium with WebGPU on SwiftShader and one page in it,
/// driven through the DevTools protocol.
pub struct Browser {
    process: Child,
    socket: tungstenite::WebSocket<TcpStream>,
    session: String,
    next: u64,
    _profile: PathBuf,
}

impl Browser {
    /// Start `chromium` on `url` and wait until the page has loaded.
    pub fn open(chromium: &Path, url: &str, profile: PathBuf) -> Browser {
        let process = Command::new(chromium)
            .args(["--headless=new", "--no-sandbox", "--no-first-run", "--disable-gpu-sandbox"])
            .args(["--enable-unsafe-webgpu", "--use-webgpu-adapter=swiftshader", "--enable-unsafe-swiftshader"])
            .args(["--enable-features=Vulkan", "--use-vulkan=swiftshader", "--disable-vulkan-surface"])
            .arg("--remote-debugging-port=0")
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromium starts");
        // Chromium writes the port it chose, and the browser's endpoint, into the profile.
        let file = profile.join("DevToolsActivePort");
        let start = Instant::now();
        let active = loop {
            if let Ok(text) = std::fs::read_to_string(&file) {
                if text.lines().count() >= 2 {
                    break text;
                }
            }
            assert!(start.elapsed() < Duration::from_secs(60), "chromium wrote no {}", file.display());
            std::thread::sleep(Duration::from_millis(100));
        };
        let mut lines = active.lines();
        let (port, path) = (lines.next().unwrap(), lines.next().unwrap());
        let stream = TcpStream::connect(("127.0.0.1", port.parse::<u16>().unwrap())).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(300))).unwrap();
        let (socket, _) = tungstenite::client(format!("ws://127.0.0.1:{port}{path}"), stream).expect("DevTools socket");
        let mut browser = Browser { process, socket, session: String::new(), next: 0, _profile: profile };
        let target = browser.call("Target.createTarget", json!({ "url": "about:blank" }), false);
        let attached =
            browser.call("Target.attachToTarget", json!({ "targetId": target["targetId"], "flatten": true }), false);
        browser.session = attached["sessionId"].as_str().unwrap().to_string();
        // Navigate returns once the new document is committed, so what is
        // evaluated next runs in it (not in the blank page before it).
        let navigated = browser.call("Page.navigate", json!({ "url": url }), true);
        assert!(navigated.get("errorText").is_none(), "{url}: {navigated}");
        browser.evaluate(
            "new Promise(done => document.readyState === 'complete' ? done(true) : addEventListener('load', () => done(true)))",
        );
        browser
    }

    /// A DevTools method's result, in the page's session or the browser's.
    fn call(&mut self, method: &str, params: Value, in_page: bool) -> Value {
        self.next += 1;
        let id = self.next;
        let mut message = json!({ "id": id, "method": method, "params": params });
        if in_page {
            message["sessionId"] = json!(self.session);
        }
        self.socket.send(tungstenite::Message::text(message.to_string())).unwrap();
        loop {
            let reply = match self.socket.read() {
                Ok(reply) => reply,
                // A signal to the test process (other tests run children
                // and threads beside this one) interrupts the blocking read
                // before it took a byte: the frame is still on the socket.
                Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => panic!("DevTools, waiting for {method}: {e}"),
            };
            let tungstenite::Message::Text(text) = reply else { continue };
            let reply: Value = serde_json::from_str(&text).unwrap();
            if reply["id"] == id {
                assert!(reply.get("error").is_none(), "{method}: {}", reply["error"]);
                return reply["result"].clone();
            }
        }
    }

    /// The value of a JavaScript expression in the page (a promise is
    /// awaited); an exception it throws fails the test with its text.
    pub fn evaluate(&mut self, expression: &str) -> Value {
        let result = self.call(
            "Runtime.evaluate",
            json!({ "expression": expression, "awaitPromise": true, "returnByValue": true }),
            true,
        );
        if let Some(exception) = result.get("exceptionDetails") {
            panic!(
                "the page threw: {}",
                exception["exception"]["description"].as_str().unwrap_or(&exception.to_string())
            );
        }
        result["result"]["value"].clone()
    }

    /// A PNG of the page as laid out at `width`×`height` CSS pixels.
    pub fn screenshot(&mut self, width: u32, height: u32) -> Vec<u8> {
        self.call(
            "Emulation.setDeviceMetricsOverride",
            json!({ "width": width, "height": height, "deviceScaleFactor": 1, "mobile": false }),
            true,
        );
        let shot = self.call("Page.captureScreenshot", json!({ "format": "png" }), true);
        data_encoding::BASE64.decode(shot["data"].as_str().unwrap().as_bytes()).expect("DevTools sends base64")
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.process.kill();
        let _ = self.process.wait();
    }
}
