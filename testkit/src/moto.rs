//! A moto S3 server on loopback, for the object-storage tests and `bench convert`: started from
//! the tests' venv (`tests/py/moto_server.py`, which `scripts/setup-python.sh` makes work), on a
//! free port, killed when dropped, and gone on its own once the process that started it exits
//! (a test binary may share one server between its tests and never drop it).

use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::{free_port, Error, Result};

/// How long moto may take to listen (it imports a lot of Python).
const START_TIMEOUT: Duration = Duration::from_secs(60);

/// A running moto server.
pub struct Moto {
    child: Child,
    /// `http://127.0.0.1:<port>`.
    pub endpoint: String,
}

impl Moto {
    /// Starts moto with `python` (the tests' venv), its log in `log`, and waits until it
    /// listens.
    pub fn start(python: &Path, root: &Path, log: &Path) -> Result<Moto> {
        let port = free_port()?;
        let script = root.join("tests/py/moto_server.py");
        let program = python.display().to_string();
        let stderr = std::fs::File::create(log).map_err(|source| Error::Process {
            program: log.display().to_string(),
            source,
        })?;
        let child = Command::new(python)
            .arg(&script)
            .arg(port.to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .spawn()
            .map_err(|source| Error::Process {
                program: program.clone(),
                source,
            })?;
        let mut moto = Moto {
            child,
            endpoint: format!("http://127.0.0.1:{port}"),
        };
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        let start = Instant::now();
        while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
            let exited = moto.child.try_wait().ok().flatten().is_some();
            if exited || start.elapsed() > START_TIMEOUT {
                let why = std::fs::read_to_string(log).unwrap_or_default();
                let last = why.lines().last().unwrap_or("no output").to_string();
                return Err(Error::Process {
                    program: format!("{program} {}", script.display()),
                    source: std::io::Error::other(format!("moto did not start: {last}")),
                });
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(moto)
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
