//! `serve`'s control thread: inputs in, one tick per control period (of the wall clock, or of
//! a simulation's `/clock`), chunks from the inference thread installed as they come, commands
//! published, the status kept.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use scaledp_policy::ActionChunk;
use scaledp_recorder::keys::RmwAttachment;
use scaledp_recorder::now_ns;
use scaledp_schema::RosMessage;
use scaledp_sim::messages;
use zenoh::Wait;

use super::shared::{lock, CommandHook, Input, Status};
use crate::controller::{Command, Controller, Request};
use crate::stats::percentile;

pub(super) struct Outputs {
    /// Per arm: pose publisher and key type, gripper publisher.
    pub arms: Vec<(
        Option<zenoh::pubsub::Publisher<'static>>,
        Option<zenoh::pubsub::Publisher<'static>>,
    )>,
    pub rmw: bool,
    pub seq: i64,
    pub status: zenoh::pubsub::Publisher<'static>,
}

/// The clock a server runs on: the wall clock, or a simulation's `/clock` (its latest value,
/// written by the clock's subscriber).
#[derive(Clone)]
pub(super) struct Clocks {
    pub sim: Option<Arc<AtomicU64>>,
}

impl Clocks {
    /// Now, on this server's clock (ns).
    pub fn now_ns(&self) -> u64 {
        self.sim
            .as_ref()
            .map_or_else(now_ns, |c| c.load(Ordering::Relaxed))
    }
}

/// The loop's state between ticks.
struct Loop {
    ctl: Controller,
    req_tx: Sender<Request>,
    res_rx: Receiver<(u64, ActionChunk, f64)>,
    out: Outputs,
    hook: Option<CommandHook>,
    clocks: Clocks,
    latencies: VecDeque<f64>,
    commanded: VecDeque<Instant>,
    // Receive time of the newest frame behind each request, and of the chunk just installed.
    frame_of_request: VecDeque<(u64, u64)>,
    fresh_chunk: Option<u64>,
    e2e: VecDeque<f64>,
    started: Instant,
    last_status: Instant,
    st: Status,
}

impl Loop {
    /// One control tick at `tick_ns` on the server's clock.
    fn tick(&mut self, tick_ns: u64, status: &Mutex<Status>) {
        let now = Instant::now();
        let period_ns = self.ctl.period_ns();
        for (index, chunk, ms) in self.res_rx.try_iter() {
            self.ctl.install(index, &chunk);
            while let Some(&(i, frame_ns)) = self.frame_of_request.front() {
                self.frame_of_request.pop_front();
                if i == index {
                    self.fresh_chunk = Some(frame_ns);
                    break;
                }
            }
            self.st.chunks += 1;
            self.latencies.push_back(ms);
            if self.latencies.len() > 200 {
                self.latencies.pop_front();
            }
            let v: Vec<f64> = self.latencies.iter().copied().collect();
            self.st.inference_ms_p50 = percentile(&v, 0.5);
            self.st.inference_ms_p99 = percentile(&v, 0.99);
            let p50_ns = self.st.inference_ms_p50.unwrap_or(0.0) * 1e6;
            self.ctl
                .set_lead_ticks((p50_ns / period_ns as f64).ceil() as u64);
        }
        let tick = self.ctl.tick(tick_ns);
        self.st.ticks += 1;
        self.st.halted_ticks += u64::from(tick.halted.is_some());
        if let Some(req) = tick.request {
            if let Some(f) = self.ctl.newest_frame_ns() {
                self.frame_of_request.push_back((req.index, f));
            }
            let _ = self.req_tx.send(req);
        }
        match self.ctl.command() {
            Ok(cmds) => {
                self.st.holding = None;
                self.st.commanded_ticks += 1;
                self.st.clamped_ticks += u64::from(cmds.iter().any(|c| c.clamped.any()));
                self.commanded.push_back(now);
                publish(&self.ctl, &mut self.out, &cmds, self.clocks.now_ns());
                if let Some(f) = self.fresh_chunk.take() {
                    self.e2e
                        .push_back(self.clocks.now_ns().saturating_sub(f) as f64 * 1e-6);
                    if self.e2e.len() > 200 {
                        self.e2e.pop_front();
                    }
                    let v: Vec<f64> = self.e2e.iter().copied().collect();
                    self.st.e2e_ms_p50 = percentile(&v, 0.5);
                    self.st.e2e_ms_p99 = percentile(&v, 0.99);
                }
                if let Some(h) = &self.hook {
                    h(tick.index, &cmds);
                }
            }
            Err(why) => self.st.holding = Some(why),
        }
        while self
            .commanded
            .front()
            .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(2))
        {
            self.commanded.pop_front();
        }
        let window = self.started.elapsed().as_secs_f64().clamp(1e-3, 2.0);
        self.st.command_rate_hz = self.commanded.len() as f64 / window;
        *lock(status) = self.st.clone();
        if self.last_status.elapsed() >= Duration::from_secs(1) {
            self.last_status = Instant::now();
            if let Ok(json) = serde_json::to_string(&self.st) {
                let _ = self.out.status.put(json).wait();
            }
        }
    }

    /// Hands an input to the controller; a clock sample returns its time.
    fn input(&mut self, input: Input) -> Option<u64> {
        match input {
            Input::Image(c, stamp, recv, data) => {
                let ty = self.ctl.rig().cameras[c].message_type();
                self.ctl.on_image(c, stamp, recv, ty, data);
                None
            }
            Input::Joints(a, g, recv, js) => {
                self.ctl.on_joint_state(a, g, recv, &js);
                None
            }
            Input::Clock(ns) => Some(ns),
        }
    }
}

/// The control thread: ticks every control period of the wall clock, or, on a simulation's
/// clock, every period of simulated time as its `/clock` passes it (a tick per period crossed,
/// none while the clock stands still).
#[allow(clippy::too_many_arguments)]
pub(super) fn control_loop(
    ctl: Controller,
    rx: Receiver<Input>,
    req_tx: Sender<Request>,
    res_rx: Receiver<(u64, ActionChunk, f64)>,
    out: Outputs,
    hook: Option<CommandHook>,
    clocks: Clocks,
    status: &Mutex<Status>,
    stop: &AtomicBool,
) {
    let period_ns = ctl.period_ns();
    let st = Status {
        dry_run: lock(status).dry_run,
        ..Status::default()
    };
    let sim = clocks.sim.is_some();
    let mut l = Loop {
        ctl,
        req_tx,
        res_rx,
        out,
        hook,
        clocks,
        latencies: VecDeque::new(),
        commanded: VecDeque::new(),
        frame_of_request: VecDeque::new(),
        fresh_chunk: None,
        e2e: VecDeque::new(),
        started: Instant::now(),
        last_status: Instant::now(),
        st,
    };
    if sim {
        let mut next: Option<u64> = None;
        while !stop.load(Ordering::Relaxed) {
            let input = match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(i) => i,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => break,
            };
            let Some(now) = l.input(input) else { continue };
            let first = *next.get_or_insert(now);
            // A clock that jumps back (a restarted simulation) starts the ticks over.
            let mut t = if now + period_ns < first { now } else { first };
            while t <= now {
                l.tick(t, status);
                t += period_ns;
            }
            next = Some(t);
        }
        return;
    }
    let period = Duration::from_nanos(period_ns);
    let mut next = Instant::now() + period;
    while !stop.load(Ordering::Relaxed) {
        match rx.recv_timeout(next.saturating_duration_since(Instant::now())) {
            Ok(input) => {
                l.input(input);
                continue;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        let now = Instant::now();
        next += period;
        if next < now {
            next = now + period; // fell behind: skip ticks rather than bunch them
        }
        l.tick(now_ns(), status);
    }
}

fn publish(ctl: &Controller, out: &mut Outputs, cmds: &[Command], stamp: u64) {
    for c in cmds {
        let arm = &ctl.rig().arms[c.arm];
        let Some((pose_pub, grip_pub)) = out.arms.get(c.arm) else {
            continue;
        };
        let mut put = |p: &zenoh::pubsub::Publisher<'static>, bytes: Vec<u8>| {
            out.seq += 1;
            let put = p.put(bytes);
            let r = if out.rmw {
                put.attachment(
                    RmwAttachment {
                        sequence_number: out.seq,
                        source_timestamp_ns: stamp as i64,
                        source_gid: vec![0x5e; 16],
                    }
                    .to_zbytes(),
                )
                .wait()
            } else {
                put.wait()
            };
            if let Err(e) = r {
                tracing::warn!("{}: {e}", p.key_expr());
            }
        };
        let m = messages::arm_command_cdr(arm, &scaledp_sim::ArmCommand::from(c), stamp);
        if let (Some(p), Some(m)) = (pose_pub, m) {
            put(p, m);
        }
        if let (Some(p), Some(g), Some(w)) = (grip_pub, &arm.gripper, c.gripper_width_m) {
            put(p, messages::gripper_command(g, w, stamp).to_cdr());
        }
    }
}
