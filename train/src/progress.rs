//! Training progress: a live indicatif bar with loss, steps/s and ETA on a
//! terminal; otherwise one compact line every few seconds (never one per batch, unlike burn-train's renderer).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How progress is shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressMode {
    /// A bar when stdout is a terminal, lines otherwise.
    Auto,
    /// Compact lines every `interval`.
    Lines,
    /// Nothing (tests).
    Quiet,
}

/// Live progress of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    lines: bool,
    interval: Duration,
    last_print: Instant,
    total: u64,
    /// Exponential moving average of steps/s.
    rate: Option<f64>,
}

impl Progress {
    /// Starts showing progress of steps `start..total`; `interval` is the gap between compact lines.
    pub fn new(mode: ProgressMode, start: u64, total: u64, interval: Duration) -> Self {
        let use_bar = mode == ProgressMode::Auto && std::io::stdout().is_terminal();
        let bar = use_bar.then(|| {
            let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stdout());
            let style = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} ETA {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar());
            bar.set_style(style);
            bar.set_position(start);
            bar
        });
        Progress {
            lines: bar.is_none() && mode != ProgressMode::Quiet,
            bar,
            interval,
            last_print: Instant::now(),
            total,
            rate: None,
        }
    }

    /// Reports that `step` finished with `loss` after `step_secs` seconds of work.
    pub fn step(&mut self, step: u64, loss: f64, step_secs: f64) {
        let inst = 1.0 / step_secs.max(1e-9);
        let rate = match self.rate {
            Some(r) => 0.9 * r + 0.1 * inst,
            None => inst,
        };
        self.rate = Some(rate);
        if let Some(bar) = &self.bar {
            bar.set_position(step);
            bar.set_message(format!("loss {loss:.4e} {rate:.2} steps/s"));
        } else if self.lines && (self.last_print.elapsed() >= self.interval || step == self.total) {
            self.last_print = Instant::now();
            println!("{}", compact_line(step, self.total, loss, rate));
        }
    }

    /// Prints a message above the bar (or as a line).
    pub fn println(&self, msg: &str) {
        match &self.bar {
            Some(bar) => bar.println(msg),
            None if self.lines => println!("{msg}"),
            None => {}
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// `step 120/1000 (12.0%) loss 3.1416e-2 4.20 steps/s ETA 3m29s`.
pub fn compact_line(step: u64, total: u64, loss: f64, steps_per_s: f64) -> String {
    let pct = 100.0 * step as f64 / total.max(1) as f64;
    let eta = (total.saturating_sub(step)) as f64 / steps_per_s.max(1e-9);
    format!(
        "step {step}/{total} ({pct:.1}%) loss {loss:.4e} {steps_per_s:.2} steps/s ETA {}",
        hms(eta)
    )
}

fn hms(secs: f64) -> String {
    let s = secs.round() as u64;
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, sec) => format!("{sec}s"),
        (0, m, sec) => format!("{m}m{sec:02}s"),
        (h, m, sec) => format!("{h}h{m:02}m{sec:02}s"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compact_line_has_loss_rate_and_eta() {
        let line = compact_line(120, 1000, 0.031416, 4.2);
        assert_eq!(line, "step 120/1000 (12.0%) loss 3.1416e-2 4.20 steps/s ETA 3m30s");
        assert_eq!(hms(3725.0), "1h02m05s");
    }
}
