//! The GPU's own clock on every kernel launch: timestamp queries written at the start and end
//! of each launch's compute pass ([`crate::gpu::Gpu::start_timing`]), read back once when
//! timing stops ([`crate::gpu::Gpu::stop_timing`]).
//!
//! Unlike the tape's profile ([`crate::Tape::enable_profiling`]), which waits for the GPU
//! after every op and so times each op with its launch latency, this waits for nothing: the
//! kernels run as they do in training, and the [`KernelTimeline`] says how long each ran
//! (`busy`), how long the GPU was between the first start and the last end (`span`), and so
//! how long it waited for the host (`span - busy`: launches recorded and submitted, uploads
//! and buffer clears, which are copies, not passes, and are not timed apart). A tape labels
//! the launches of each op with the op's name (forward) or `name (backward)` while timing is
//! on, so a row is one op's kernel.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};

/// Whether some [`crate::gpu::Gpu`] is timing its launches (checked by tapes before labelling).
pub(crate) static ACTIVE: AtomicBool = AtomicBool::new(false);

/// Whether launches are being timed (a cheap check for callers that label them).
pub(crate) fn active() -> bool {
    ACTIVE.load(Ordering::Relaxed)
}

/// Which op made a launch: its name and whether its gradient rule did; `None` for a launch
/// made outside a tape (or not labelled yet).
pub type OpLabel = Option<(&'static str, bool)>;

/// One launch whose start and end the GPU wrote.
#[derive(Clone, Debug)]
pub(crate) struct TimedLaunch {
    /// The kernel's name.
    pub kernel: &'static str,
    /// The op that made it (`None` until a tape labels it).
    pub op: OpLabel,
}

/// Launches being timed: the open batch's query set, the batches resolved and waiting to be
/// read, and every launch in order.
pub(crate) struct Timing {
    /// The query set of the batch being recorded (two queries a launch).
    pub open: Option<wgpu::QuerySet>,
    /// Launches of the batch being recorded.
    pub open_launches: u32,
    /// Resolved batches: the buffer their timestamps are copied into, and their launches.
    pub resolved: Vec<(wgpu::Buffer, u32)>,
    /// Every timed launch, in launch order.
    pub launches: Vec<TimedLaunch>,
    /// `launches[..labelled]` have been given their op's label.
    pub labelled: usize,
}

impl Timing {
    pub fn new() -> Self {
        Self { open: None, open_launches: 0, resolved: Vec::new(), launches: Vec::new(), labelled: 0 }
    }

    /// Gives `op` to every launch since the last label.
    pub fn label(&mut self, op: OpLabel) {
        for l in &mut self.launches[self.labelled..] {
            l.op = op;
        }
        self.labelled = self.launches.len();
    }
}

/// One op's kernel in a [`KernelTimeline`]: its launches and their GPU time.
#[derive(Clone, Debug, PartialEq)]
pub struct TimelineRow {
    /// The op that launched it (`name`, `name (backward)`), or `-` for launches made outside a
    /// tape (the optimiser's clipping, Adam and non-finite check).
    pub label: String,
    /// The kernel (a WGSL entry point of `gpu/wgsl`).
    pub kernel: &'static str,
    /// Launches.
    pub launches: usize,
    /// Seconds the GPU ran them, start to end of each launch, summed.
    pub seconds: f64,
}

/// What the GPU's clock saw between [`crate::gpu::Gpu::start_timing`] and
/// [`crate::gpu::Gpu::stop_timing`] (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelTimeline {
    /// One row per op and kernel, the longest first.
    pub rows: Vec<TimelineRow>,
    /// Launches timed.
    pub launches: usize,
    /// Seconds the GPU ran kernels: every launch's start to end, summed.
    pub busy_s: f64,
    /// Seconds from the first launch's start to the last one's end.
    pub span_s: f64,
}

impl KernelTimeline {
    /// Builds the timeline from each launch's `(start, end)` in the GPU's ticks of
    /// `period_ns` nanoseconds.
    pub(crate) fn new(launches: &[TimedLaunch], ticks: &[(u64, u64)], period_ns: f64) -> Self {
        let secs = |t: u64| t as f64 * period_ns * 1e-9;
        let mut by_row: HashMap<(OpLabel, &'static str), (usize, f64)> = HashMap::new();
        let mut busy = 0.0;
        for (l, &(start, end)) in launches.iter().zip(ticks) {
            let s = secs(end.saturating_sub(start));
            busy += s;
            let e = by_row.entry((l.op, l.kernel)).or_default();
            e.0 += 1;
            e.1 += s;
        }
        let label = |op: OpLabel| match op {
            None => "-".to_string(),
            Some((name, false)) => name.to_string(),
            Some((name, true)) => format!("{name} (backward)"),
        };
        let first = ticks.iter().map(|t| t.0).min().unwrap_or(0);
        let last = ticks.iter().map(|t| t.1).max().unwrap_or(0);
        let mut rows: Vec<TimelineRow> = by_row
            .into_iter()
            .map(|((op, kernel), (n, s))| TimelineRow { label: label(op), kernel, launches: n, seconds: s })
            .collect();
        rows.sort_by(|a, b| {
            b.seconds.total_cmp(&a.seconds).then_with(|| (&a.label, a.kernel).cmp(&(&b.label, b.kernel)))
        });
        Self { rows, launches: launches.len(), busy_s: busy, span_s: secs(last.saturating_sub(first)) }
    }

    /// Seconds per kernel over every op, the longest first.
    pub fn by_kernel(&self) -> Vec<(&'static str, usize, f64)> {
        let mut m: HashMap<&'static str, (usize, f64)> = HashMap::new();
        for r in &self.rows {
            let e = m.entry(r.kernel).or_default();
            e.0 += r.launches;
            e.1 += r.seconds;
        }
        let mut v: Vec<_> = m.into_iter().map(|(k, (n, s))| (k, n, s)).collect();
        v.sort_by(|a, b| b.2.total_cmp(&a.2).then_with(|| a.0.cmp(b.0)));
        v
    }
}

impl std::fmt::Display for KernelTimeline {
    /// The totals, then the kernels, then the `limit` longest op rows (all with `{:#}`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |s: f64| s * 1e3;
        let share = |s: f64| if self.busy_s > 0.0 { 100.0 * s / self.busy_s } else { 0.0 };
        writeln!(
            f,
            "gpu timeline: {} launches, kernels busy {:.3} ms of a {:.3} ms span ({:.1}% busy; the rest: waiting \
             for the host, copies, barriers)",
            self.launches,
            ms(self.busy_s),
            ms(self.span_s),
            if self.span_s > 0.0 { 100.0 * self.busy_s / self.span_s } else { 0.0 }
        )?;
        writeln!(f, "  by kernel:")?;
        for (k, n, s) in self.by_kernel() {
            writeln!(f, "    {k:<24} {n:>6} launches {:>10.3} ms {:>5.1}%", ms(s), share(s))?;
        }
        let limit = if f.alternate() { self.rows.len() } else { 25 };
        writeln!(f, "  by op and kernel ({} of {} rows):", limit.min(self.rows.len()), self.rows.len())?;
        for r in self.rows.iter().take(limit) {
            let op = format!("{} / {}", r.label, r.kernel);
            writeln!(
                f,
                "    {op:<48} {:>6} launches {:>10.3} ms {:>5.1}%",
                r.launches,
                ms(r.seconds),
                share(r.seconds)
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_sum_launches_by_op_and_kernel_and_the_span_covers_the_gaps() {
        let l = |kernel, op: OpLabel| TimedLaunch { kernel, op };
        let (linear, add) = (Some(("linear", false)), Some(("add", true)));
        let launches = [l("matmul", linear), l("binary", add), l("matmul", linear), l("adam", None)];
        // Ticks of 2 ns: 10-20, a gap, 30-35, 35-55, 100-101.
        let ticks = [(10, 20), (30, 35), (35, 55), (100, 101)];
        let t = KernelTimeline::new(&launches, &ticks, 2.0);
        assert_eq!(t.launches, 4);
        assert!((t.busy_s - 2.0 * 36.0e-9).abs() < 1e-18, "{}", t.busy_s);
        assert!((t.span_s - 2.0 * 91.0e-9).abs() < 1e-18, "{}", t.span_s);
        let r = &t.rows[0];
        assert_eq!((r.label.as_str(), r.kernel, r.launches), ("linear", "matmul", 2));
        assert!((r.seconds - 60.0e-9).abs() < 1e-18, "{}", r.seconds);
        assert_eq!(t.rows[1].label, "add (backward)");
        assert_eq!(t.rows[2].label, "-", "an unlabelled launch");
        let k = t.by_kernel()[0];
        assert_eq!((k.0, k.1), ("matmul", 2));
        assert!((k.2 - 60.0e-9).abs() < 1e-18);
        let text = t.to_string();
        assert!(text.contains("4 launches") && text.contains("linear / matmul"), "{text}");
    }

    #[test]
    fn a_label_goes_to_the_launches_since_the_last_one() {
        let mut t = Timing::new();
        let launch = |kernel| TimedLaunch { kernel, op: None };
        t.launches.push(launch("a"));
        t.label(Some(("first", false)));
        t.launches.push(launch("b"));
        t.launches.push(launch("c"));
        t.label(Some(("second", true)));
        t.label(Some(("third (no launches)", false)));
        let labels: Vec<OpLabel> = t.launches.iter().map(|l| l.op).collect();
        assert_eq!(labels, [Some(("first", false)), Some(("second", true)), Some(("second", true))]);
    }
}
