//! A loopback HTTP/1.1 proxy in front of an S3 endpoint that tests use to see and break the
//! traffic: it counts the bytes of responses, records each request line, can cut requests with
//! a body (uploads) halfway through, can go down (refusing every connection), and can call a
//! hook on each request before it is forwarded. Requests are parsed only as far as their
//! headers and `Content-Length` (what object_store's S3 client sends); responses are copied
//! as they come.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// Called with each request line (e.g. `GET /bucket/key HTTP/1.1`) before it is forwarded.
pub type Hook = Arc<dyn Fn(&str) + Send + Sync>;

/// What the proxy sees and does, shared with its threads.
#[derive(Default)]
pub struct ProxyState {
    /// Refuse every new connection (and cut the open ones at their next request).
    pub down: AtomicBool,
    /// Requests with a body still to cut halfway (counts down).
    pub cut_uploads: AtomicUsize,
    /// Bytes of responses passed back.
    pub bytes_down: AtomicU64,
    /// Request lines seen, in order.
    pub requests: Mutex<Vec<String>>,
    /// See [`Hook`].
    pub hook: Mutex<Option<Hook>>,
}

/// A running proxy (its threads live as long as the process).
pub struct Proxy {
    /// `http://127.0.0.1:<port>`.
    pub endpoint: String,
    /// What it sees and does.
    pub state: Arc<ProxyState>,
}

impl Proxy {
    /// A proxy in front of `upstream` (`http://host:port`).
    ///
    /// # Panics
    /// When no loopback port can be bound.
    pub fn start(upstream: &str) -> Proxy {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a loopback port");
        let endpoint = format!("http://{}", listener.local_addr().expect("its address"));
        let upstream = upstream.trim_start_matches("http://").to_string();
        let state = Arc::new(ProxyState::default());
        let s = state.clone();
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { return };
                if s.down.load(Ordering::SeqCst) {
                    let _ = client.shutdown(Shutdown::Both);
                    continue;
                }
                let Ok(server) = TcpStream::connect(&upstream) else {
                    continue;
                };
                let (s1, s2) = (s.clone(), s.clone());
                let (c2, sv2) = match (client.try_clone(), server.try_clone()) {
                    (Ok(c), Ok(sv)) => (c, sv),
                    _ => continue,
                };
                std::thread::spawn(move || requests(client, server, &s1));
                std::thread::spawn(move || responses(sv2, c2, &s2));
            }
        });
        Proxy { endpoint, state }
    }

    /// The request lines seen so far.
    pub fn requests(&self) -> Vec<String> {
        self.state
            .requests
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Sets the hook (see [`Hook`]).
    pub fn set_hook(&self, hook: Option<Hook>) {
        *self.state.hook.lock().unwrap_or_else(|p| p.into_inner()) = hook;
    }
}

fn close(a: &TcpStream, b: &TcpStream) {
    let _ = a.shutdown(Shutdown::Both);
    let _ = b.shutdown(Shutdown::Both);
}

/// Client → server: one request at a time, headers then `Content-Length` bytes of body.
fn requests(client: TcpStream, mut server: TcpStream, state: &ProxyState) {
    let Ok(read_half) = client.try_clone() else {
        return;
    };
    let mut from = BufReader::new(read_half);
    loop {
        let mut head = Vec::new();
        let mut length = 0u64;
        loop {
            let mut line = String::new();
            match from.read_line(&mut line) {
                Ok(0) | Err(_) => return close(&client, &server),
                Ok(_) => {}
            }
            if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                length = v.trim().parse().unwrap_or(0);
            }
            let end = line == "\r\n";
            head.extend_from_slice(line.as_bytes());
            if end {
                break;
            }
        }
        let text = String::from_utf8_lossy(&head);
        let request_line = text.lines().next().unwrap_or_default().to_string();
        if state.down.load(Ordering::SeqCst) {
            return close(&client, &server);
        }
        let hook = state.hook.lock().unwrap_or_else(|p| p.into_inner()).clone();
        if let Some(hook) = hook {
            hook(&request_line);
        }
        state
            .requests
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(request_line);
        let cut = length > 0
            && state
                .cut_uploads
                .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |k| k.checked_sub(1))
                .is_ok();
        if server.write_all(&head).is_err() {
            return close(&client, &server);
        }
        let send = if cut { length / 2 } else { length };
        let copied = std::io::copy(&mut (&mut from).take(send), &mut server);
        if cut || copied.map_or(true, |n| n < send) {
            return close(&client, &server);
        }
    }
}

/// Server → client: bytes as they come, counted.
fn responses(mut server: TcpStream, mut client: TcpStream, state: &ProxyState) {
    let mut buf = vec![0u8; 64 << 10];
    loop {
        let n = match server.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        state.bytes_down.fetch_add(n as u64, Ordering::Relaxed);
        if client.write_all(&buf[..n]).is_err() {
            break;
        }
    }
    close(&server, &client);
}
