//! Simulators in another process, driven as robots: a rig with a `[simulator]` table
//! (`metaworld/<task>`) is simulated by a Python process (`sim/bridges/scaledp_bridge`, the
//! simulator's own physics, rendering and scripted expert) that answers the bridge protocol on
//! its stdin/stdout; [`Bridge`] is this side of it.
//!
//! The simulation advances only when asked: [`Bridge::reset`] starts the episode of a seed,
//! [`Bridge::step`] applies one control step's commands (a TCP target in the arm's base frame
//! and a gripper opening, as a policy or teleoperator sends them) and [`Bridge::expert_step`]
//! one step of the simulator's scripted expert, reporting what it commanded in the same form.
//! Every reply is an [`Observation`] on the simulation's clock: the arms' joints, the cameras'
//! images (tightly packed RGB, in the rig's camera order) and the task's success.
//!
//! [`episodes`] publishes it on Zenoh as zenoh-bridge-ros2dds would (the expert's episodes
//! through the recorder: `scaledp collect`); [`live`] runs it on Zenoh in a loop of its own with
//! the simulation's `/clock` (`scaledp sim`, `eval --live`); `deploy` evaluates policies on it in
//! simulated time.

pub mod episodes;
pub mod live;
mod process;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};

use glam::{DMat3, DMat4, DQuat, DVec3};
use scaledp_schema::Rig;
use serde::Deserialize;
use serde_json::{json, Value};

pub use process::{python, PYTHON_ENV, VENV};

use crate::world::ArmCommand;
use crate::{Error, Result};

/// What the simulator says of itself.
#[derive(Debug, Clone, Deserialize)]
pub struct Hello {
    /// `metaworld`.
    pub env: String,
    /// Its task (`assembly-v3`).
    pub task: String,
    /// Simulated time of one step (s).
    pub step_s: f64,
    /// Steps in an episode at most.
    pub max_steps: u64,
    /// Package versions (`metaworld`, `mujoco`, …): recorded with every result.
    #[serde(default)]
    pub versions: BTreeMap<String, String>,
    /// A task whose progress counts stages: the name of stage 1, 2, …, its last the success
    /// (gym-aloha's rewards 1–4; MetaWorld's `near_object`, `grasp_success`, `success` flags).
    /// Empty when the simulator names none.
    #[serde(default)]
    pub stages: Vec<String>,
    /// The cameras as the simulator renders them.
    #[serde(default)]
    pub cameras: Vec<HelloCamera>,
}

/// One camera as the simulator renders it.
#[derive(Debug, Clone, Deserialize)]
pub struct HelloCamera {
    /// Its name in the simulator's model.
    pub name: String,
    /// Its vertical field of view (degrees), after the rig's `vertical_fov_deg`.
    pub fovy_deg: f64,
}

/// One arm as the simulator measured it.
#[derive(Debug, Clone, Deserialize)]
pub struct ArmReading {
    /// Joint positions (rad), in the rig's joint order.
    pub q: Vec<f64>,
    /// The gripper's joint positions, in the rig's gripper joint order.
    pub gripper_q: Vec<f64>,
    /// The simulator's own flange pose in the base frame: x, y, z, qw, qx, qy, qz.
    pub flange: [f64; 7],
}

impl ArmReading {
    /// The simulator's flange pose as a transform.
    pub fn flange_pose(&self) -> DMat4 {
        let f = &self.flange;
        let q = DQuat::from_xyzw(f[4], f[5], f[6], f[3]).normalize();
        DMat4::from_rotation_translation(q, DVec3::new(f[0], f[1], f[2]))
    }
}

#[derive(Deserialize)]
struct Header {
    ok: bool,
    #[serde(default)]
    error: Option<String>,
    #[serde(default)]
    step: u64,
    #[serde(default)]
    arms: Vec<ArmReading>,
    #[serde(default)]
    success: bool,
    #[serde(default)]
    succeeded: bool,
    #[serde(default)]
    reward: f64,
    #[serde(default)]
    stage: Option<f64>,
    #[serde(default)]
    done: bool,
    #[serde(default)]
    render: bool,
    #[serde(default)]
    commands: Option<Vec<Value>>,
}

/// The simulation after a reset or a step.
#[derive(Debug, Clone)]
pub struct Observation {
    /// Steps since the reset.
    pub step: u64,
    /// Per arm, in rig order.
    pub arms: Vec<ArmReading>,
    /// The task is a success now.
    pub success: bool,
    /// The task has been a success at some step of this episode.
    pub succeeded: bool,
    /// The task's reward at this step.
    pub reward: f64,
    /// The stage the task is at this step when [`Hello::stages`] names them (0: none yet): the
    /// simulator's `stage`, else its reward (gym-aloha's reward counts stages).
    pub stage: f64,
    /// The episode has taken the simulator's last step.
    pub done: bool,
    /// Per rig camera, its RGB pixels (empty when the step was not rendered).
    pub images: Vec<Vec<u8>>,
    /// `expert_step` only: what the expert commanded, per arm.
    pub commands: Vec<ArmCommand>,
}

/// A simulator process for one rig.
pub struct Bridge {
    name: String,
    hello: Hello,
    /// Shared with [`Killer`]s: a call blocked on a hung simulator's stdout holds no lock.
    child: Arc<Mutex<Child>>,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
    stderr: Arc<Mutex<Vec<String>>>,
    image_bytes: Vec<usize>,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge").field("rig", &self.name).finish()
    }
}

/// A transform as the protocol's `[x, y, z, qw, qx, qy, qz]`.
fn pose_array(t: &DMat4) -> [f64; 7] {
    let p = t.w_axis.truncate();
    let q = DQuat::from_mat3(&DMat3::from_mat4(*t)).normalize();
    [p.x, p.y, p.z, q.w, q.x, q.y, q.z]
}

fn command_json(c: &ArmCommand) -> Value {
    json!({
        "pose": c.pose.map(|p| pose_array(&p)),
        "joints": c.joints,
        "gripper_width_m": c.gripper_width_m,
    })
}

fn command_from_json(v: &Value) -> ArmCommand {
    let pose = v["pose"].as_array().and_then(|a| {
        let f: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
        (f.len() == 7).then(|| {
            let q = DQuat::from_xyzw(f[4], f[5], f[6], f[3]).normalize();
            DMat4::from_rotation_translation(q, DVec3::new(f[0], f[1], f[2]))
        })
    });
    let joints = v["joints"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect());
    ArmCommand {
        pose,
        joints,
        gripper_width_m: v["gripper_width_m"].as_f64(),
    }
}

impl Bridge {
    /// Starts the simulator of `rig` (which must have a `[simulator]`), with every camera of
    /// the rig (one size for all).
    pub fn spawn(rig: &Rig) -> Result<Self> {
        let name = rig.name.clone();
        let bad = |reason: String| Error::Bridge {
            what: name.clone(),
            reason,
        };
        let sim = rig
            .simulator
            .as_ref()
            .ok_or_else(|| bad("the rig names no [simulator]".into()))?;
        let (w, h) = match rig.cameras.first() {
            Some(c) => (c.width, c.height),
            None => (64, 64),
        };
        if let Some(c) = rig.cameras.iter().find(|c| (c.width, c.height) != (w, h)) {
            return Err(bad(format!(
                "camera {} is {}×{}: a simulator renders every camera at one size ({w}×{h})",
                c.name, c.width, c.height
            )));
        }
        if let Some(c) = rig.cameras.iter().find(|c| c.encoding() != "rgb8") {
            return Err(bad(format!(
                "camera {} is {}: a simulator publishes rgb8",
                c.name,
                c.encoding()
            )));
        }
        let cameras: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
        // `name=degrees` for each camera the rig zooms.
        let fovy: Vec<String> = rig
            .cameras
            .iter()
            .filter_map(|c| c.vertical_fov_deg.map(|f| format!("{}={f}", c.name)))
            .collect();
        let py = python()?;
        let src = process::sources_dir()?;
        let mut child = Command::new(&py)
            .args(["-m", "scaledp_bridge", "--env"])
            .arg(sim.bridge.to_string())
            .arg("--task")
            .arg(&sim.task)
            .arg("--cameras")
            .arg(cameras.join(","))
            .arg("--size")
            .arg(format!("{w}x{h}"))
            .arg("--fovy")
            .arg(fovy.join(","))
            .env("PYTHONPATH", &src)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| bad(format!("starting {}: {e}", py.display())))?;
        let (Some(stdin), Some(stdout), Some(stderr)) =
            (child.stdin.take(), child.stdout.take(), child.stderr.take())
        else {
            return Err(bad("the bridge's pipes were not opened".into()));
        };
        // The bridge's stderr (warnings, tracebacks): kept for error messages, the last lines.
        let tail = Arc::new(Mutex::new(Vec::new()));
        let keep = tail.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr)
                .lines()
                .map_while(std::result::Result::ok)
            {
                tracing::debug!(target: "scaledp_sim::bridge", "{line}");
                let mut t = keep.lock().unwrap_or_else(|p| p.into_inner());
                t.push(line);
                let n = t.len();
                if n > 20 {
                    t.drain(..n - 20);
                }
            }
        });
        let mut bridge = Bridge {
            name: name.clone(),
            hello: Hello {
                env: sim.bridge.to_string(),
                task: sim.task.clone(),
                step_s: 0.0,
                max_steps: 0,
                versions: BTreeMap::new(),
                stages: Vec::new(),
                cameras: Vec::new(),
            },
            child: Arc::new(Mutex::new(child)),
            stdin,
            stdout: BufReader::new(stdout),
            stderr: tail,
            image_bytes: rig
                .cameras
                .iter()
                .map(|c| (c.width * c.height * 3) as usize)
                .collect(),
        };
        let (v, _) = bridge.call(&json!({"op": "hello"}), "starting")?;
        bridge.hello =
            serde_json::from_value(v).map_err(|e| bad(format!("the bridge's hello: {e}")))?;
        if !(bridge.hello.step_s > 0.0 && bridge.hello.step_s.is_finite()) {
            return Err(bad(format!("step of {} s", bridge.hello.step_s)));
        }
        for cam in &rig.cameras {
            let drawn = bridge.hello.cameras.iter().find(|c| c.name == cam.name);
            if let (Some(_), None) = (cam.vertical_fov_deg, drawn) {
                return Err(bad(format!(
                    "camera {} is zoomed by the rig, and the bridge does not say it renders it",
                    cam.name
                )));
            }
            if let (Some(want), Some(got)) = (cam.vertical_fov_deg, drawn) {
                if (want - got.fovy_deg).abs() > 1e-6 {
                    return Err(bad(format!(
                        "camera {} renders at {}° of vertical field, not the rig's {want}°",
                        cam.name, got.fovy_deg
                    )));
                }
            }
        }
        Ok(bridge)
    }

    /// What the simulator said of itself.
    pub fn hello(&self) -> &Hello {
        &self.hello
    }

    /// A handle that kills this simulator process from another thread.
    pub fn killer(&self) -> Killer {
        Killer(self.child.clone())
    }

    /// One step of simulated time (ns).
    pub fn step_ns(&self) -> u64 {
        (self.hello.step_s * 1e9).round() as u64
    }

    /// The last lines the bridge wrote to stderr.
    fn stderr_tail(&self) -> String {
        let t = self.stderr.lock().unwrap_or_else(|p| p.into_inner());
        t.iter()
            .rev()
            .find(|l| !l.trim().is_empty() && !l.contains("Warning"))
            .cloned()
            .unwrap_or_default()
    }

    fn call(&mut self, req: &Value, what: &str) -> Result<(Value, Vec<u8>)> {
        let ctx = format!("{}: {what}", self.name);
        let died = |b: &mut Bridge, e: String| {
            let status = lock_child(&b.child).try_wait().ok().flatten();
            let tail = b.stderr_tail();
            Error::Bridge {
                what: ctx.clone(),
                reason: match status {
                    Some(s) => format!("the bridge exited ({s}): {tail}"),
                    None => format!("{e} {tail}"),
                },
            }
        };
        let mut line = req.to_string();
        line.push('\n');
        if let Err(e) = self
            .stdin
            .write_all(line.as_bytes())
            .and_then(|()| self.stdin.flush())
        {
            // Let the stderr reader catch the traceback before it is quoted.
            std::thread::sleep(std::time::Duration::from_millis(100));
            return Err(died(self, e.to_string()));
        }
        let mut len = [0u8; 4];
        if let Err(e) = self.stdout.read_exact(&mut len) {
            std::thread::sleep(std::time::Duration::from_millis(100));
            return Err(died(self, e.to_string()));
        }
        let mut head = vec![0u8; u32::from_le_bytes(len) as usize];
        self.stdout
            .read_exact(&mut head)
            .map_err(|e| died(self, e.to_string()))?;
        let v: Value = serde_json::from_slice(&head).map_err(|e| Error::Bridge {
            what: ctx.clone(),
            reason: format!("a reply that is not JSON: {e}"),
        })?;
        let n = v["payload"].as_u64().unwrap_or(0) as usize;
        let mut payload = vec![0u8; n];
        self.stdout
            .read_exact(&mut payload)
            .map_err(|e| died(self, e.to_string()))?;
        if v["ok"].as_bool() != Some(true) {
            return Err(Error::Bridge {
                what: ctx,
                reason: v["error"].as_str().unwrap_or("failed").to_string(),
            });
        }
        Ok((v, payload))
    }

    fn observation(&mut self, req: Value, what: &str) -> Result<Observation> {
        let (v, payload) = self.call(&req, what)?;
        let ctx = || format!("{}: {what}", self.name);
        let h: Header = serde_json::from_value(v).map_err(|e| Error::Bridge {
            what: ctx(),
            reason: format!("reply: {e}"),
        })?;
        debug_assert!(h.ok && h.error.is_none());
        let mut images = Vec::with_capacity(self.image_bytes.len());
        if h.render {
            let mut at = 0;
            for &n in &self.image_bytes {
                let Some(img) = payload.get(at..at + n) else {
                    return Err(Error::Bridge {
                        what: ctx(),
                        reason: format!(
                            "{} image bytes, the rig's cameras need more",
                            payload.len()
                        ),
                    });
                };
                images.push(img.to_vec());
                at += n;
            }
        }
        let commands = h
            .commands
            .unwrap_or_default()
            .iter()
            .map(command_from_json)
            .collect();
        Ok(Observation {
            step: h.step,
            arms: h.arms,
            success: h.success,
            succeeded: h.succeeded,
            reward: h.reward,
            stage: h.stage.unwrap_or(h.reward),
            done: h.done,
            images,
            commands,
        })
    }

    /// The episode of `seed`, its first observation (rendered when `render`).
    pub fn reset(&mut self, seed: u64, render: bool) -> Result<Observation> {
        self.observation(
            json!({"op": "reset", "seed": seed, "render": render}),
            &format!("reset to seed {seed}"),
        )
    }

    /// One step under `commands` (one per arm; `None` fields hold the last command).
    pub fn step(&mut self, commands: &[ArmCommand], render: bool) -> Result<Observation> {
        let cmds: Vec<Value> = commands.iter().map(command_json).collect();
        self.observation(
            json!({"op": "step", "commands": cmds, "render": render}),
            "step",
        )
    }

    /// One step of the simulator's scripted expert; [`Observation::commands`] holds what it
    /// commanded.
    pub fn expert_step(&mut self, render: bool) -> Result<Observation> {
        self.observation(
            json!({"op": "expert_step", "render": render}),
            "expert step",
        )
    }
}

/// Kills a bridge's simulator process from another thread: the way out of a call blocked on a
/// simulator that hangs (the call then fails, as on any simulator that exits).
#[derive(Clone)]
pub struct Killer(Arc<Mutex<Child>>);

impl Killer {
    /// Kills the process (nothing if it has exited).
    pub fn kill(&self) {
        let _ = lock_child(&self.0).kill();
    }
}

fn lock_child(c: &Mutex<Child>) -> std::sync::MutexGuard<'_, Child> {
    c.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = self.stdin.write_all(b"{\"op\": \"close\"}\n");
        let _ = self.stdin.flush();
        // A bridge that does not close within a second is killed.
        for _ in 0..20 {
            if matches!(lock_child(&self.child).try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let mut child = lock_child(&self.child);
        let _ = child.kill();
        let _ = child.wait();
    }
}
