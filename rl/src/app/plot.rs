//! Line plots as standalone SVG, written by hand (no plotting crate): learning curves of a
//! run (`curve.svg`) and of a sweep (`meben report`).
//!
//! ```
//! use rl::app::plot::LinePlot;
//! let svg = LinePlot::new("team_reach/1_ant")
//!     .x_label("env steps")
//!     .y_label("success %")
//!     .y_range(0.0, 100.0)
//!     .series_with_band("shnn", vec![(0.0, 10.0), (1e6, 40.0)], vec![(8.0, 12.0), (35.0, 45.0)])
//!     .series("mlp_hn", vec![(0.0, 5.0), (1e6, 20.0)])
//!     .to_svg();
//! assert!(svg.starts_with("<svg"));
//! ```
//!
//! Axes get "nice" ticks (steps of 1, 2 or 5 times a power of ten); tick labels of large
//! values carry a suffix (`2.5M`, `500k`, `1G`). Points with a non-finite coordinate are
//! skipped; an axis whose values are all equal is widened around them; a plot without any
//! point shows empty axes and "no data".

use std::fmt::Write as _;

/// The colours series are drawn in, in order (the Tableau 10 palette, distinguishable for
/// most colour-vision deficiencies); the 11th series reuses the first colour.
pub const PALETTE: [&str; 10] =
    ["#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac"];

/// Opacity of the shaded band around a series.
const BAND_OPACITY: f64 = 0.2;
/// Left edge of the plotting area (room for the y tick labels and the y label).
const PLOT_LEFT: f64 = 76.0;
/// Width of the plotting area.
const PLOT_WIDTH: f64 = 500.0;
/// Top edge of the plotting area (room for the title).
const PLOT_TOP: f64 = 44.0;
/// Height of the plotting area.
const PLOT_HEIGHT: f64 = 300.0;
/// Below the plotting area: tick labels and the x label.
const BOTTOM_MARGIN: f64 = 56.0;
/// Longest series name shown in the legend (longer ones are shortened with an ellipsis).
const LEGEND_MAX_CHARS: usize = 48;
/// Approximate width of a character of the 12 px sans-serif legend font.
const CHAR_WIDTH: f64 = 6.8;
/// Approximate number of ticks per axis.
const TARGET_TICKS: usize = 5;

/// One line of a [`LinePlot`].
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Shown in the legend.
    pub name: String,
    /// `(x, y)` points, drawn joined in order; points with a non-finite coordinate are
    /// skipped.
    pub points: Vec<(f64, f64)>,
    /// `(lower, upper)` per point (same length as `points`), shaded as a translucent band;
    /// entries with a non-finite bound are skipped.
    pub band: Option<Vec<(f64, f64)>>,
}

/// A line plot with a title, axis labels, a legend and any number of series (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinePlot {
    title: String,
    x_label: String,
    y_label: String,
    y_range: Option<(f64, f64)>,
    series: Vec<Series>,
}

impl LinePlot {
    /// An empty plot with a title.
    pub fn new(title: impl Into<String>) -> Self {
        LinePlot { title: title.into(), ..LinePlot::default() }
    }

    /// Sets the label under the x axis.
    pub fn x_label(mut self, label: impl Into<String>) -> Self {
        self.x_label = label.into();
        self
    }

    /// Sets the label beside the y axis.
    pub fn y_label(mut self, label: impl Into<String>) -> Self {
        self.y_label = label.into();
        self
    }

    /// Fixes the y axis to `[lo, hi]` (e.g. `0..100` for percentages) instead of fitting it
    /// to the data; lines are clipped to it. Ignored unless both are finite and `lo < hi`.
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = (lo.is_finite() && hi.is_finite() && lo < hi).then_some((lo, hi));
        self
    }

    /// Adds a line, coloured by its position ([`PALETTE`]).
    pub fn series(mut self, name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        self.series.push(Series { name: name.into(), points, band: None });
        self
    }

    /// Adds a line with a shaded band: `band[i] = (lower, upper)` at `points[i].0` (extra
    /// entries on either side are ignored).
    pub fn series_with_band(mut self, name: impl Into<String>, points: Vec<(f64, f64)>, band: Vec<(f64, f64)>) -> Self {
        self.series.push(Series { name: name.into(), points, band: Some(band) });
        self
    }

    /// Adds a prepared [`Series`].
    pub fn push(&mut self, series: Series) {
        self.series.push(series);
    }

    /// The series added so far.
    pub fn series_list(&self) -> &[Series] {
        &self.series
    }

    /// The plot as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for s in &self.series {
            for p in s.points.iter().filter(|p| finite(p)) {
                xs.push(p.0);
                ys.push(p.1);
            }
            for (p, b) in s.points.iter().zip(s.band.iter().flatten()) {
                if p.0.is_finite() && finite(b) {
                    ys.push(b.0);
                    ys.push(b.1);
                }
            }
        }
        let x_axis = Axis::fit(&xs);
        let y_axis = match self.y_range {
            Some((lo, hi)) => Axis::fixed(lo, hi),
            None => Axis::fit(&ys),
        };
        let px = |x: f64| PLOT_LEFT + (x - x_axis.lo) / (x_axis.hi - x_axis.lo) * PLOT_WIDTH;
        let py = |y: f64| PLOT_TOP + PLOT_HEIGHT - (y - y_axis.lo) / (y_axis.hi - y_axis.lo) * PLOT_HEIGHT;

        let names: Vec<String> = self.series.iter().map(|s| shorten(&s.name)).collect();
        let legend_chars = names.iter().map(|n| n.chars().count()).max().unwrap_or(0);
        let legend_left = PLOT_LEFT + PLOT_WIDTH + 18.0;
        let width = if self.series.is_empty() {
            PLOT_LEFT + PLOT_WIDTH + 24.0
        } else {
            legend_left + 30.0 + legend_chars as f64 * CHAR_WIDTH + 12.0
        };
        let height = (PLOT_TOP + PLOT_HEIGHT + BOTTOM_MARGIN).max(PLOT_TOP + 20.0 * self.series.len() as f64 + 16.0);
        let (right, bottom) = (PLOT_LEFT + PLOT_WIDTH, PLOT_TOP + PLOT_HEIGHT);

        let mut svg = String::new();
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(svg, r#"<rect x="0" y="0" width="{width:.0}" height="{height:.0}" fill="white"/>"#);
        let _ = writeln!(
            svg,
            r#"<defs><clipPath id="plot-area"><rect x="{PLOT_LEFT}" y="{PLOT_TOP}" width="{PLOT_WIDTH}" height="{PLOT_HEIGHT}"/></clipPath></defs>"#
        );
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="24" text-anchor="middle" font-size="15" font-weight="bold">{}</text>"#,
            PLOT_LEFT + PLOT_WIDTH / 2.0,
            escape(&self.title)
        );

        // Grid and tick labels.
        for (t, label) in x_axis.ticks.iter().zip(&x_axis.labels) {
            let x = px(*t);
            let _ = writeln!(
                svg,
                r##"<line x1="{x:.1}" y1="{PLOT_TOP}" x2="{x:.1}" y2="{bottom}" stroke="#e0e0e0"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                bottom + 16.0,
                escape(label)
            );
        }
        for (t, label) in y_axis.ticks.iter().zip(&y_axis.labels) {
            let y = py(*t);
            let _ = writeln!(
                svg,
                r##"<line x1="{PLOT_LEFT}" y1="{y:.1}" x2="{right}" y2="{y:.1}" stroke="#e0e0e0"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                PLOT_LEFT - 6.0,
                y + 4.0,
                escape(label)
            );
        }
        let _ = writeln!(
            svg,
            r##"<rect x="{PLOT_LEFT}" y="{PLOT_TOP}" width="{PLOT_WIDTH}" height="{PLOT_HEIGHT}" fill="none" stroke="#444"/>"##
        );
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            PLOT_LEFT + PLOT_WIDTH / 2.0,
            bottom + 40.0,
            escape(&self.x_label)
        );
        let (ylx, yly) = (20.0, PLOT_TOP + PLOT_HEIGHT / 2.0);
        let _ = writeln!(
            svg,
            r#"<text x="{ylx}" y="{yly}" text-anchor="middle" transform="rotate(-90 {ylx} {yly})">{}</text>"#,
            escape(&self.y_label)
        );
        if xs.is_empty() {
            let _ = writeln!(
                svg,
                r##"<text x="{:.1}" y="{:.1}" text-anchor="middle" fill="#888">no data</text>"##,
                PLOT_LEFT + PLOT_WIDTH / 2.0,
                PLOT_TOP + PLOT_HEIGHT / 2.0
            );
        }

        // Bands first, so every line is drawn over every band.
        let _ = writeln!(svg, r#"<g clip-path="url(#plot-area)">"#);
        for (i, s) in self.series.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let Some(band) = &s.band else { continue };
            let pts: Vec<(f64, f64, f64)> = s
                .points
                .iter()
                .zip(band)
                .filter(|(p, b)| p.0.is_finite() && finite(b))
                .map(|(p, b)| (px(p.0), py(b.0), py(b.1)))
                .collect();
            match pts.len() {
                0 => {}
                1 => {
                    // A single point: the band is a vertical error bar.
                    let (x, lo, hi) = pts[0];
                    let _ = writeln!(
                        svg,
                        r#"<path d="M{x:.1},{lo:.1}L{x:.1},{hi:.1}" stroke="{colour}" stroke-opacity="0.5" stroke-width="3" fill="none"/>"#
                    );
                }
                _ => {
                    let mut d = String::new();
                    for (k, (x, _, hi)) in pts.iter().enumerate() {
                        let _ = write!(d, "{}{x:.1},{hi:.1}", if k == 0 { 'M' } else { 'L' });
                    }
                    for (x, lo, _) in pts.iter().rev() {
                        let _ = write!(d, "L{x:.1},{lo:.1}");
                    }
                    d.push('Z');
                    let _ =
                        writeln!(svg, r#"<path d="{d}" fill="{colour}" fill-opacity="{BAND_OPACITY}" stroke="none"/>"#);
                }
            }
        }
        for (i, s) in self.series.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = s.points.iter().filter(|p| finite(p)).map(|p| (px(p.0), py(p.1))).collect();
            // One point, or all points at one place: a dot, since a line would not show.
            let single = !pts.is_empty() && pts.iter().all(|p| *p == pts[0]);
            match pts.len() {
                0 => {}
                _ if single => {
                    let _ =
                        writeln!(svg, r#"<circle cx="{:.1}" cy="{:.1}" r="3.5" fill="{colour}"/>"#, pts[0].0, pts[0].1);
                }
                _ => {
                    let mut d = String::new();
                    for (k, (x, y)) in pts.iter().enumerate() {
                        let _ = write!(d, "{}{x:.1},{y:.1}", if k == 0 { 'M' } else { 'L' });
                    }
                    let _ = writeln!(
                        svg,
                        r#"<path d="{d}" fill="none" stroke="{colour}" stroke-width="2" stroke-linejoin="round"/>"#
                    );
                }
            }
        }
        let _ = writeln!(svg, "</g>");

        // Legend.
        for (i, (s, name)) in self.series.iter().zip(&names).enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let y = PLOT_TOP + 10.0 + 20.0 * i as f64;
            if s.band.is_some() {
                let _ = writeln!(
                    svg,
                    r#"<rect x="{legend_left}" y="{:.1}" width="22" height="10" fill="{colour}" fill-opacity="{BAND_OPACITY}"/>"#,
                    y - 5.0
                );
            }
            let _ = writeln!(
                svg,
                r#"<line x1="{legend_left}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{colour}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                legend_left + 22.0,
                legend_left + 30.0,
                y + 4.0,
                escape(name)
            );
        }
        svg.push_str("</svg>\n");
        svg
    }
}

/// An axis: its range, tick positions and tick labels.
#[derive(Clone, Debug, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    labels: Vec<String>,
}

impl Axis {
    /// An axis covering `values` (non-finite ones ignored), widened to whole tick steps.
    fn fit(values: &[f64]) -> Axis {
        let (mut lo, mut hi) = values
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        } else if lo == hi {
            let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.5 };
            (lo, hi) = (lo - pad, hi + pad);
        }
        let step = nice_step(hi - lo);
        let (lo, hi) = ((lo / step).floor() * step, (hi / step).ceil() * step);
        Axis::with_ticks(lo, hi, step)
    }

    /// An axis over exactly `[lo, hi]` (`lo < hi`, both finite).
    fn fixed(lo: f64, hi: f64) -> Axis {
        Axis::with_ticks(lo, hi, nice_step(hi - lo))
    }

    fn with_ticks(lo: f64, hi: f64, step: f64) -> Axis {
        let first = (lo / step - 1e-9).ceil() as i64;
        let last = (hi / step + 1e-9).floor() as i64;
        let ticks: Vec<f64> = (first..=last).map(|i| i as f64 * step).collect();
        let labels = tick_labels(&ticks, step);
        Axis { lo, hi, ticks, labels }
    }
}

/// The tick step for a span: 1, 2 or 5 times a power of ten, giving about
/// [`TARGET_TICKS`] ticks.
fn nice_step(span: f64) -> f64 {
    let raw = span / TARGET_TICKS as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let f = raw / magnitude;
    let nice = if f <= 1.0 + 1e-9 {
        1.0
    } else if f <= 2.0 + 1e-9 {
        2.0
    } else if f <= 5.0 + 1e-9 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// Labels of ticks `step` apart: as many decimals as the step needs, with a `k`/`M`/`G`
/// suffix when the largest tick is at least ten thousand (`0` never has one).
fn tick_labels(ticks: &[f64], step: f64) -> Vec<String> {
    let largest = ticks.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    let (unit, suffix) = if largest >= 1e9 {
        (1e9, "G")
    } else if largest >= 1e6 {
        (1e6, "M")
    } else if largest >= 1e4 {
        (1e3, "k")
    } else {
        (1.0, "")
    };
    let decimals = (-(step / unit).log10() - 1e-9).ceil().max(0.0) as usize;
    ticks
        .iter()
        .map(|t| match format_trimmed(t / unit, decimals) {
            zero if zero == "0" => zero,
            v => format!("{v}{suffix}"),
        })
        .collect()
}

/// `v` with `decimals` decimals, trailing zeros (and a bare point) removed, no `-0`.
fn format_trimmed(v: f64, decimals: usize) -> String {
    let mut s = format!("{v:.decimals$}");
    if s.contains('.') {
        s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    if s == "-0" { "0".into() } else { s }
}

/// A legend name of at most [`LEGEND_MAX_CHARS`] characters.
fn shorten(name: &str) -> String {
    if name.chars().count() <= LEGEND_MAX_CHARS {
        name.to_string()
    } else {
        let mut s: String = name.chars().take(LEGEND_MAX_CHARS - 1).collect();
        s.push('…');
        s
    }
}

/// Escapes text for SVG (XML) content and attributes.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that every tag opened is closed, in order (enough XML to catch mistakes of
    /// this writer, which never emits comments, CDATA or `>` inside attributes).
    fn assert_balanced(svg: &str) {
        let mut stack: Vec<String> = Vec::new();
        let mut rest = svg;
        while let Some(start) = rest.find('<') {
            let end = rest[start..].find('>').expect("unterminated tag") + start;
            let tag = &rest[start + 1..end];
            if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(stack.pop().as_deref(), Some(name), "mismatched </{name}>");
            } else if !tag.ends_with('/') {
                stack.push(tag.split_whitespace().next().unwrap().to_string());
            }
            rest = &rest[end + 1..];
        }
        assert!(stack.is_empty(), "unclosed tags {stack:?}");
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "non-finite coordinate in {svg}");
    }

    #[test]
    fn nice_steps_and_labels() {
        assert_eq!(nice_step(50e6), 10e6);
        assert_eq!(nice_step(1.0), 0.2);
        assert_eq!(nice_step(100.0), 20.0);
        assert_eq!(nice_step(12.5e6), 5e6);
        let a = Axis::fit(&[0.0, 2.3e6]);
        assert_eq!(a.labels, ["0", "0.5M", "1M", "1.5M", "2M", "2.5M"]);
        let a = Axis::fixed(0.0, 1.0);
        assert_eq!(a.labels, ["0", "0.2", "0.4", "0.6", "0.8", "1"]);
        let a = Axis::fit(&[-3.0, 3.0]);
        assert_eq!(a.labels.first().map(|s| s.as_str()), Some("-4"));
        assert_eq!(Axis::fit(&[0.0, 40_000.0]).labels[1], "10k");
        assert_eq!(Axis::fit(&[0.0, 3e9]).labels.last().map(|s| s.as_str()), Some("3G"));
    }

    #[test]
    fn degenerate_axes() {
        let a = Axis::fit(&[5.0, 5.0]);
        assert!(a.lo < 5.0 && a.hi > 5.0);
        let a = Axis::fit(&[0.0]);
        assert!(a.lo < 0.0 && a.hi > 0.0);
        let a = Axis::fit(&[f64::NAN]);
        assert_eq!((a.lo, a.hi), (0.0, 1.0));
        assert!(!a.ticks.is_empty());
    }

    #[test]
    fn svg_with_bands_and_edge_cases() {
        let svg = LinePlot::new("a <title> & more")
            .x_label("env steps")
            .y_label("success %")
            .y_range(0.0, 100.0)
            .series_with_band("shnn", vec![(0.0, 10.0), (1e6, f64::NAN), (2e6, 60.0)], vec![(5.0, 15.0); 3])
            .series("one point", vec![(1e6, 50.0)])
            .series_with_band("one point band", vec![(1e6, 50.0)], vec![(40.0, 60.0)])
            .series("empty", vec![])
            .to_svg();
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains("fill-opacity=\"0.2\""), "band polygon missing");
        assert!(svg.contains("a &lt;title&gt; &amp; more"));
        assert!(svg.contains("<circle"));
        assert!(svg.contains(">2M<"));
        assert_balanced(&svg);
    }

    #[test]
    fn empty_and_flat_plots_are_valid() {
        for plot in [
            LinePlot::new("empty"),
            LinePlot::new("no points").series("a", vec![]),
            LinePlot::new("flat").series("a", vec![(1.0, 3.0), (1.0, 3.0)]).series("b", vec![(1.0, 3.0)]),
            LinePlot::new("all nan").series("a", vec![(f64::NAN, 1.0), (1.0, f64::INFINITY)]),
        ] {
            let svg = plot.to_svg();
            assert!(svg.starts_with("<svg"));
            assert_balanced(&svg);
        }
        assert!(LinePlot::new("e").to_svg().contains("no data"));
    }

    #[test]
    fn palette_cycles_and_long_names_shorten() {
        let mut p = LinePlot::new("many");
        for i in 0..12 {
            p.push(Series {
                name: "x".repeat(60 + i),
                points: vec![(i as f64, 1.0), (i as f64 + 1.0, 2.0)],
                band: None,
            });
        }
        let svg = p.to_svg();
        assert_eq!(svg.matches(PALETTE[0]).count(), 4, "series 0 and 10: line and legend each");
        assert!(svg.contains('…'));
        assert_balanced(&svg);
    }
}
