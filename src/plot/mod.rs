//! Minimal, dependency-free SVG line charts for the project's figures: one or more panels in a
//! grid, each with axes, "nice" ticks, axis labels with units, a legend and several series
//! (solid or dashed lines, optional markers). Pure: rendering returns a `String`.
//!
//! ```
//! use ddct::plot::{Figure, Panel, Series};
//! let mut p = Panel::new("Torque", "x_to (mm)", "T (N·m)");
//! p.add(Series::line("25 °C", vec![(4.0, 0.0), (6.0, 120.0)]));
//! let svg = Figure::new("demo", 1).panel(p).to_svg();
//! assert!(svg.starts_with("<svg"));
//! ```

pub mod paper;

use std::fmt::Write as _;

/// Categorical palette (colour-blind friendly, Okabe–Ito).
pub(crate) const PALETTE: [&str; 8] = [
    "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442",
];

/// `n` colours from light to dark along a blue ramp ("darker = higher", as in the paper).
pub fn ramp(n: usize) -> Vec<String> {
    (0..n)
        .map(|i| {
            let t = if n <= 1 {
                1.0
            } else {
                i as f64 / (n - 1) as f64
            };
            let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
            format!(
                "#{:02X}{:02X}{:02X}",
                lerp(150.0, 8.0),
                lerp(190.0, 29.0),
                lerp(230.0, 88.0)
            )
        })
        .collect()
}

/// Where the legend box sits inside the axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LegendPos {
    #[default]
    TopLeft,
    TopRight,
    BottomLeft,
    BottomRight,
}

/// Line style of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Style {
    #[default]
    Solid,
    Dashed,
    Dotted,
    /// Markers only.
    Markers,
}

/// One data series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// CSS colour; `None` takes the palette colour of its index.
    pub color: Option<String>,
    pub style: Style,
    pub width: f64,
    /// A step in x larger than this leaves the line open (a dropout is not drawn across).
    pub max_gap: Option<f64>,
    /// Drawn as a staircase (held until the next point): states and gears.
    pub steps: bool,
}

impl Series {
    /// A solid line.
    pub fn line(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.into(),
            points,
            color: None,
            style: Style::Solid,
            width: 1.8,
            max_gap: None,
            steps: false,
        }
    }
    /// Leaves the line open over x steps larger than `gap`.
    pub fn max_gap(mut self, gap: f64) -> Self {
        self.max_gap = Some(gap);
        self
    }
    /// Draws the series as a staircase.
    pub fn steps(mut self) -> Self {
        self.steps = true;
        self
    }
    pub fn color(mut self, c: impl Into<String>) -> Self {
        self.color = Some(c.into());
        self
    }
    pub fn style(mut self, s: Style) -> Self {
        self.style = s;
        self
    }
}

/// One set of axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub title: String,
    /// Axis labels, with units, e.g. "x_to (mm)".
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Fixed ranges; `None` fits the data (with nice rounding).
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    pub legend: bool,
    /// Legend title, e.g. "θ_c".
    pub legend_title: String,
    pub legend_pos: LegendPos,
    /// Named y ticks (a lane per value: states, gears) instead of numbers.
    pub y_labels: Vec<(f64, String)>,
    /// Vertical event markers at x with a label (fault codes).
    pub markers: Vec<(f64, String)>,
}

impl Panel {
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            x_range: None,
            y_range: None,
            legend: true,
            legend_title: String::new(),
            legend_pos: LegendPos::TopLeft,
            y_labels: Vec::new(),
            markers: Vec::new(),
        }
    }
    /// Named y ticks: one lane per `(value, name)`.
    pub fn y_labels(mut self, labels: Vec<(f64, String)>) -> Self {
        self.y_labels = labels;
        self
    }
    /// Adds a vertical event marker.
    pub fn marker(&mut self, x: f64, label: impl Into<String>) -> &mut Self {
        self.markers.push((x, label.into()));
        self
    }
    pub fn add(&mut self, s: Series) -> &mut Self {
        self.series.push(s);
        self
    }
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }
    pub fn legend_pos(mut self, pos: LegendPos) -> Self {
        self.legend_pos = pos;
        self
    }
    pub fn legend_title(mut self, t: impl Into<String>) -> Self {
        self.legend_title = t.into();
        self
    }
}

/// A figure: panels laid out on a grid with `cols` columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    pub title: String,
    pub cols: usize,
    pub panels: Vec<Panel>,
    /// Size of one panel (px).
    pub panel_width: f64,
    pub panel_height: f64,
}

impl Figure {
    pub fn new(title: impl Into<String>, cols: usize) -> Self {
        Figure {
            title: title.into(),
            cols: cols.max(1),
            panels: Vec::new(),
            panel_width: 520.0,
            panel_height: 380.0,
        }
    }
    pub fn panel(mut self, p: Panel) -> Self {
        self.panels.push(p);
        self
    }

    /// Renders the figure as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let n = self.panels.len().max(1);
        let cols = self.cols.min(n);
        let rows = n.div_ceil(cols);
        let top = if self.title.is_empty() { 10.0 } else { 40.0 };
        let w = cols as f64 * self.panel_width;
        let h = top + rows as f64 * self.panel_height;
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="DejaVu Sans, Arial, sans-serif">"#
        );
        let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
        if !self.title.is_empty() {
            let _ = writeln!(
                s,
                r#"<text x="{}" y="26" font-size="{:.1}" text-anchor="middle" font-weight="bold">{}</text>"#,
                w / 2.0,
                fitted_font_size(&self.title, 17.0, w - 20.0),
                esc(&self.title)
            );
        }
        for (k, p) in self.panels.iter().enumerate() {
            let x0 = (k % cols) as f64 * self.panel_width;
            let y0 = top + (k / cols) as f64 * self.panel_height;
            render_panel(&mut s, p, x0, y0, self.panel_width, self.panel_height);
        }
        s.push_str("</svg>\n");
        s
    }
}

/// The font size (≤ `size`) at which `text` fits `width` pixels (average glyph ≈ 0.6 em), so a
/// long title shrinks instead of running off the figure.
fn fitted_font_size(text: &str, size: f64, width: f64) -> f64 {
    let em = 0.6 * text.chars().count() as f64;
    if em * size <= width || em == 0.0 {
        size
    } else {
        (width / em).max(7.0)
    }
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// "Nice" tick step for a range and a target count.
pub(crate) fn nice_step(span: f64, target: usize) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nf = if f < 1.5 {
        1.0
    } else if f < 3.0 {
        2.0
    } else if f < 7.0 {
        5.0
    } else {
        10.0
    };
    nf * mag
}

/// Ticks covering `[lo, hi]` with a nice step.
pub(crate) fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let step = nice_step(hi - lo, target);
    let start = (lo / step - 1e-9).ceil() * step;
    let mut v = Vec::new();
    let mut t = start;
    while t <= hi + 1e-9 * step && v.len() < 100 {
        v.push(if t.abs() < 1e-12 * step { 0.0 } else { t });
        t += step;
    }
    v
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        format!("{v:.decimals$}")
    }
}

fn data_range(p: &Panel, x: bool) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in &p.series {
        for &(a, b) in &s.points {
            let v = if x { a } else { b };
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 * (hi.abs() + lo.abs()).max(1e-12) {
        return (lo - 0.5, hi + 0.5);
    }
    let step = nice_step(hi - lo, 6);
    ((lo / step).floor() * step, (hi / step).ceil() * step)
}

/// The runs of `pts` between x steps larger than `gap`.
fn split_at_gaps(pts: &[(f64, f64)], gap: Option<f64>) -> Vec<&[(f64, f64)]> {
    let Some(gap) = gap else {
        return vec![pts];
    };
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..pts.len() {
        if pts[k].0 - pts[k - 1].0 > gap {
            out.push(&pts[start..k]);
            start = k;
        }
    }
    out.push(&pts[start..]);
    out
}

/// Ramer–Douglas–Peucker in screen space: the points a polyline needs to stay within `tol`
/// pixels of the original (a smooth curve of thousands of samples needs a few hundred).
fn simplify(pts: &[(f64, f64)], tol: f64) -> Vec<(f64, f64)> {
    if pts.len() < 3 {
        return pts.to_vec();
    }
    let mut keep = vec![false; pts.len()];
    keep[0] = true;
    keep[pts.len() - 1] = true;
    let mut stack = vec![(0usize, pts.len() - 1)];
    while let Some((a, b)) = stack.pop() {
        let (p, q) = (pts[a], pts[b]);
        let (dx, dy) = (q.0 - p.0, q.1 - p.1);
        let len = dx.hypot(dy);
        let dist = |r: (f64, f64)| {
            if len == 0.0 {
                (r.0 - p.0).hypot(r.1 - p.1)
            } else {
                ((r.0 - p.0) * dy - (r.1 - p.1) * dx).abs() / len
            }
        };
        let far = (a + 1..b)
            .map(|k| (k, dist(pts[k])))
            .max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((k, d)) = far {
            if d > tol {
                keep[k] = true;
                stack.push((a, k));
                stack.push((k, b));
            }
        }
    }
    pts.iter()
        .zip(keep)
        .filter_map(|(p, k)| k.then_some(*p))
        .collect()
}

/// A staircase through `pts`: each value held until the next point.
fn staircase(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(pts.len() * 2);
    for (k, &p) in pts.iter().enumerate() {
        if k > 0 && pts[k - 1].1 != p.1 {
            out.push((p.0, pts[k - 1].1));
        }
        if k == 0 || k + 1 == pts.len() || pts[k - 1].1 != p.1 {
            out.push(p);
        }
    }
    out
}

/// Screen points reduced to at most four per half-pixel column (first, lowest, highest, last,
/// in x order): the drawn line is the same, the file a fraction of the size.
fn decimate(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(pts.len().min(4096));
    let mut k = 0;
    while k < pts.len() {
        let col = (pts[k].0 * 2.0).floor();
        let mut j = k;
        while j + 1 < pts.len() && (pts[j + 1].0 * 2.0).floor() == col {
            j += 1;
        }
        let bucket = &pts[k..=j];
        let lo = bucket
            .iter()
            .enumerate()
            .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        let hi = bucket
            .iter()
            .enumerate()
            .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        let mut keep = vec![0, bucket.len() - 1];
        keep.extend(lo.map(|x| x.0));
        keep.extend(hi.map(|x| x.0));
        keep.sort_unstable();
        keep.dedup();
        out.extend(keep.into_iter().map(|i| bucket[i]));
        k = j + 1;
    }
    out
}

/// A panel's plot area on the page and the data ranges it shows.
struct Frame {
    px: f64,
    py: f64,
    pw: f64,
    ph: f64,
    xl: f64,
    xh: f64,
    yl: f64,
    yh: f64,
}

impl Frame {
    fn of(p: &Panel, x0: f64, y0: f64, w: f64, h: f64) -> Frame {
        let (ml, mr, mt, mb) = (70.0, 20.0, 34.0, 52.0);
        let (xl, xh) = p.x_range.unwrap_or_else(|| data_range(p, true));
        let (yl, yh) = p.y_range.unwrap_or_else(|| data_range(p, false));
        Frame {
            px: x0 + ml,
            py: y0 + mt,
            pw: w - ml - mr,
            ph: h - mt - mb,
            xl,
            xh,
            yl,
            yh,
        }
    }

    /// Page x of the data value `v`.
    fn sx(&self, v: f64) -> f64 {
        self.px + (v - self.xl) / (self.xh - self.xl) * self.pw
    }

    /// Page y of the data value `v`.
    fn sy(&self, v: f64) -> f64 {
        self.py + self.ph - (v - self.yl) / (self.yh - self.yl) * self.ph
    }
}

/// The colour of series `k` (its own, else the palette's).
fn series_color(k: usize, ser: &Series) -> String {
    ser.color
        .clone()
        .unwrap_or_else(|| PALETTE[k % PALETTE.len()].to_string())
}

/// The SVG dash attribute of a line style.
fn dash(style: Style) -> &'static str {
    match style {
        Style::Dashed => r#" stroke-dasharray="7,4""#,
        Style::Dotted => r#" stroke-dasharray="2,3""#,
        _ => "",
    }
}

fn render_panel(s: &mut String, p: &Panel, x0: f64, y0: f64, w: f64, h: f64) {
    let f = Frame::of(p, x0, y0, w, h);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" font-size="{:.1}" text-anchor="middle">{}</text>"#,
        f.px + f.pw / 2.0,
        y0 + 22.0,
        fitted_font_size(&p.title, 14.0, w - 10.0),
        esc(&p.title)
    );
    render_grid(s, p, &f);
    render_markers(s, p, &f);
    render_axes(s, p, &f, x0, y0, h);
    render_series(s, p, &f, x0, y0);
    if p.legend && !p.series.is_empty() {
        render_legend(s, p, &f);
    }
}

/// The grid lines and tick labels (the panel's own y labels where it has them).
fn render_grid(s: &mut String, p: &Panel, f: &Frame) {
    let (px, py, pw, ph) = (f.px, f.py, f.pw, f.ph);
    let xt = ticks(f.xl, f.xh, 6);
    let yt = ticks(f.yl, f.yh, 6);
    let xstep = nice_step(f.xh - f.xl, 6);
    let ystep = nice_step(f.yh - f.yl, 6);
    for &t in &xt {
        let x = f.sx(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.2}" y1="{py:.2}" x2="{x:.2}" y2="{:.2}" stroke="#e4e4e4"/><text x="{x:.2}" y="{:.2}" font-size="11" text-anchor="middle">{}</text>"##,
            py + ph,
            py + ph + 16.0,
            fmt_tick(t, xstep)
        );
    }
    let y_ticks: Vec<(f64, String)> = if p.y_labels.is_empty() {
        yt.iter().map(|&t| (t, fmt_tick(t, ystep))).collect()
    } else {
        p.y_labels.clone()
    };
    for (t, label) in &y_ticks {
        let y = f.sy(*t);
        let _ = writeln!(
            s,
            r##"<line x1="{px:.2}" y1="{y:.2}" x2="{:.2}" y2="{y:.2}" stroke="#e4e4e4"/><text x="{:.2}" y="{:.2}" font-size="11" text-anchor="end">{}</text>"##,
            px + pw,
            px - 6.0,
            y + 4.0,
            esc(label)
        );
    }
}

/// The event markers: red vertical lines with their labels, those inside the x range.
fn render_markers(s: &mut String, p: &Panel, f: &Frame) {
    let (px, py, pw, ph) = (f.px, f.py, f.pw, f.ph);
    for (t, label) in &p.markers {
        let x = f.sx(*t);
        if x < px || x > px + pw {
            continue;
        }
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{py:.1}" x2="{x:.1}" y2="{:.1}" stroke="#c00" stroke-width="1.2"/><text x="{:.1}" y="{:.1}" font-size="10" fill="#c00" transform="rotate(-90 {:.1} {:.1})" text-anchor="end">{}</text>"##,
            py + ph,
            x - 3.0,
            py + 4.0,
            x - 3.0,
            py + 4.0,
            esc(label)
        );
    }
}

/// The plot area's frame and the axis labels.
fn render_axes(s: &mut String, p: &Panel, f: &Frame, x0: f64, y0: f64, h: f64) {
    let (px, py, pw, ph) = (f.px, f.py, f.pw, f.ph);
    let _ = writeln!(
        s,
        r##"<rect x="{px:.2}" y="{py:.2}" width="{pw:.2}" height="{ph:.2}" fill="none" stroke="#333"/>"##
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.2}" y="{:.2}" font-size="13" text-anchor="middle">{}</text>"#,
        px + pw / 2.0,
        y0 + h - 12.0,
        esc(&p.x_label)
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.2}" y="{:.2}" font-size="13" text-anchor="middle" transform="rotate(-90 {:.2} {:.2})">{}</text>"#,
        x0 + 18.0,
        py + ph / 2.0,
        x0 + 18.0,
        py + ph / 2.0,
        esc(&p.y_label)
    );
}

/// The series, clipped to the plot area: markers as circles, lines split at their gaps (as
/// stairs for states), decimated and simplified to 0.3 px.
fn render_series(s: &mut String, p: &Panel, f: &Frame, x0: f64, y0: f64) {
    let (px, py, pw, ph) = (f.px, f.py, f.pw, f.ph);
    let clip = format!("clip{}_{}", x0 as i64, y0 as i64);
    let _ = writeln!(
        s,
        r#"<clipPath id="{clip}"><rect x="{px:.2}" y="{py:.2}" width="{pw:.2}" height="{ph:.2}"/></clipPath>"#
    );
    for (k, ser) in p.series.iter().enumerate() {
        let color = series_color(k, ser);
        let raw: Vec<(f64, f64)> = ser
            .points
            .iter()
            .copied()
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .collect();
        if ser.style == Style::Markers {
            let pts: Vec<(f64, f64)> = raw.iter().map(|&(a, b)| (f.sx(a), f.sy(b))).collect();
            for (a, b) in &pts {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{a:.2}" cy="{b:.2}" r="2.6" fill="{color}" clip-path="url(#{clip})"/>"#
                );
            }
            continue;
        }
        let mut d = String::new();
        for run in split_at_gaps(&raw, ser.max_gap) {
            let run = if ser.steps {
                staircase(run)
            } else {
                run.to_vec()
            };
            let screen: Vec<(f64, f64)> = run.iter().map(|&(a, b)| (f.sx(a), f.sy(b))).collect();
            for (i, (a, b)) in simplify(&decimate(&screen), 0.3).iter().enumerate() {
                let _ = write!(d, "{}{a:.1},{b:.1} ", if i == 0 { "M" } else { "L" });
            }
        }
        let _ = writeln!(
            s,
            r#"<path d="{}" fill="none" stroke="{color}" stroke-width="{}"{} clip-path="url(#{clip})"/>"#,
            d.trim_end(),
            ser.width,
            dash(ser.style)
        );
    }
}

/// The legend box at the panel's legend corner inside the axes: its title, then a line sample
/// and the name of each series.
fn render_legend(s: &mut String, p: &Panel, f: &Frame) {
    let (px, py, pw, ph) = (f.px, f.py, f.pw, f.ph);
    let rows = p.series.len() + usize::from(!p.legend_title.is_empty());
    let lw = 12.0
        + 30.0
        + 7.0
            * p.series
                .iter()
                .map(|x| x.name.chars().count())
                .chain(std::iter::once(p.legend_title.chars().count()))
                .max()
                .unwrap_or(4) as f64;
    let lh = 8.0 + 16.0 * rows as f64;
    let (lx, ly) = match p.legend_pos {
        LegendPos::TopLeft => (px + 8.0, py + 8.0),
        LegendPos::TopRight => (px + pw - 8.0 - lw, py + 8.0),
        LegendPos::BottomLeft => (px + 8.0, py + ph - 8.0 - lh),
        LegendPos::BottomRight => (px + pw - 8.0 - lw, py + ph - 8.0 - lh),
    };
    let _ = writeln!(
        s,
        r##"<rect x="{lx:.2}" y="{ly:.2}" width="{lw:.2}" height="{:.2}" fill="white" fill-opacity="0.85" stroke="#999"/>"##,
        lh
    );
    let mut y = ly + 16.0;
    if !p.legend_title.is_empty() {
        let _ = writeln!(
            s,
            r#"<text x="{:.2}" y="{y:.2}" font-size="11" font-weight="bold">{}</text>"#,
            lx + 6.0,
            esc(&p.legend_title)
        );
        y += 16.0;
    }
    for (k, ser) in p.series.iter().enumerate() {
        let color = series_color(k, ser);
        let _ = writeln!(
            s,
            r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" stroke="{color}" stroke-width="2.2"{}/><text x="{:.2}" y="{:.2}" font-size="11">{}</text>"#,
            lx + 6.0,
            y - 4.0,
            lx + 30.0,
            y - 4.0,
            dash(ser.style),
            lx + 36.0,
            y,
            esc(&ser.name)
        );
        y += 16.0;
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn dropouts_split_lines_and_states_draw_as_stairs() {
        let pts = [(0.0, 1.0), (0.01, 1.0), (0.2, 2.0), (0.21, 2.0)];
        let runs = split_at_gaps(&pts, Some(0.05));
        assert_eq!(runs, vec![&pts[..2], &pts[2..]]);
        assert_eq!(split_at_gaps(&pts, None).len(), 1);
        let st = staircase(&[(0.0, 1.0), (1.0, 1.0), (2.0, 3.0), (3.0, 3.0)]);
        assert_eq!(st, vec![(0.0, 1.0), (2.0, 1.0), (2.0, 3.0), (3.0, 3.0)]);
    }

    #[test]
    fn simplified_lines_stay_within_the_tolerance() {
        // A sine of 5 000 screen points: far fewer kept, none of the dropped further than 0.3 px
        // from the kept polyline.
        let pts: Vec<(f64, f64)> = (0..5000)
            .map(|k| {
                let x = k as f64 * 0.12;
                (x, 100.0 + 80.0 * (x / 40.0).sin())
            })
            .collect();
        let kept = simplify(&decimate(&pts), 0.3);
        assert!(kept.len() < 300, "{}", kept.len());
        for p in &pts {
            let seg = kept
                .windows(2)
                .find(|w| w[0].0 <= p.0 && p.0 <= w[1].0)
                .unwrap();
            let (dx, dy) = (seg[1].0 - seg[0].0, seg[1].1 - seg[0].1);
            let d = ((p.0 - seg[0].0) * dy - (p.1 - seg[0].1) * dx).abs() / dx.hypot(dy);
            assert!(d <= 0.3 + 1e-9, "{p:?}: {d} px off");
        }
    }

    use super::*;

    #[test]
    fn long_titles_shrink_to_fit() {
        assert_eq!(fitted_font_size("short", 17.0, 400.0), 17.0);
        let long = "x".repeat(100);
        let f = fitted_font_size(&long, 17.0, 800.0);
        assert!(f < 17.0 && 0.6 * 100.0 * f <= 800.0 + 1e-9, "{f}");
    }

    #[test]
    fn nice_ticks() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(nice_step(0.8, 4), 0.2);
        let t = ticks(3.3, 7.2, 6);
        assert!(t.first().unwrap() >= &3.3 && t.last().unwrap() <= &7.2);
    }

    #[test]
    fn renders_panels_series_and_legend() {
        let mut a = Panel::new("A", "x (mm)", "y (N)");
        a.add(Series::line("one", vec![(0.0, 0.0), (1.0, 2.0)]));
        a.add(Series::line("two", vec![(0.0, 1.0), (1.0, 1.5)]).style(Style::Dashed));
        let b = Panel::new("B", "t (s)", "T (°C)");
        let svg = Figure::new("fig <1>", 2).panel(a).panel(b).to_svg();
        assert!(svg.contains("fig &lt;1&gt;"));
        assert_eq!(svg.matches("<path").count(), 2);
        assert!(svg.contains(">one<") && svg.contains(">two<"));
        assert!(svg.contains("x (mm)") && svg.contains("T (°C)"));
        assert!(svg.trim_end().ends_with("</svg>"));
    }

    /// An event marker inside the x range is a red line at its place with its label, one outside
    /// is left out; markers-only series are circles, one per finite point.
    #[test]
    fn markers_inside_the_range_are_drawn() {
        let mut p = Panel::new("P", "t (s)", "v")
            .x_range(0.0, 10.0)
            .y_range(0.0, 1.0);
        p.add(
            Series::line("pts", vec![(1.0, 0.5), (2.0, f64::NAN), (3.0, 0.2)])
                .style(Style::Markers),
        );
        p.marker(5.0, "F<12>");
        p.marker(12.0, "late");
        let svg = Figure::new("", 1).panel(p).to_svg();
        // The plot area spans x 70…500 of a 520 px panel: t = 5 s is at 285.
        assert!(svg.contains(r#"<line x1="285.0""#), "{svg}");
        assert!(svg.contains("F&lt;12&gt;") && !svg.contains("late"));
        assert_eq!(svg.matches("<circle").count(), 2);
    }
}
