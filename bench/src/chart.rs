//! Charts as SVG, drawn with plotters and laid out to be read at a glance:
//! tick labels as people write numbers (10,000, 0.5), several labelled ticks
//! on log axes, optional labels beside points, and a legend that covers no
//! data (inside the plot where a corner is free, otherwise to its right).

mod layout;
mod ticks;

use layout::{Obstacles, Px, Rect, text_size};
use plotters::coord::Shift;
use plotters::coord::combinators::LogCoord;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::ops::Range;
use std::path::Path;

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// The canvas without a legend beside it.
const SIZE: (u32, u32) = (760, 480);
const FONT: &str = "sans-serif";
/// Font sizes as plotters takes them; its SVG backend writes `size / 1.24`
/// pixels (see `px`).
const CAPTION: f64 = 22.0;
const TICK: f64 = 16.0;
const AXIS: f64 = 17.0;
const POINT: f64 = 15.0;
const LEGEND: f64 = 16.0;

/// Roughly the width in pixels of the plot (the canvas less the margins and
/// the y axis labels), for spacing the x axis labels. (The real size is
/// known only once the chart is built, which needs the ticks first.)
const X_ROOM: i32 = 620;
/// Roughly the height in pixels of the plot (the canvas less the title,
/// the margins and the x axis labels), for spacing the y axis labels.
const Y_ROOM: i32 = 360;

/// The pixel height of text that plotters was given `size` for.
fn px(size: f64) -> f64 {
    size / 1.24
}

/// A named series of (x, y) points, optionally with a label for each point
/// (such as the setting that produced it), drawn beside its marker.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// The label of `points[i]` is `labels[i]`; missing or empty labels are
    /// not drawn.
    pub labels: Vec<String>,
}

impl Series {
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>) -> Series {
        Series {
            name: name.into(),
            points,
            labels: Vec::new(),
        }
    }

    pub fn with_labels(mut self, labels: Vec<String>) -> Series {
        self.labels = labels;
        self
    }

    /// The points that can be drawn on these axes, each with its label.
    fn drawable(&self, log_x: bool, log_y: bool) -> Vec<((f64, f64), &str)> {
        self.points
            .iter()
            .enumerate()
            .filter(|&(_, &(x, y))| {
                x.is_finite() && y.is_finite() && (!log_x || x > 0.0) && (!log_y || y > 0.0)
            })
            .map(|(i, &p)| (p, self.labels.get(i).map_or("", |s| s.as_str())))
            .collect()
    }
}

fn err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("chart: {e}")
}

/// Which axes are logarithmic.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Linear,
    LogY,
    LogLog,
}

/// One axis: its range, labelled ticks and unlabelled grid lines.
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    ticks: Vec<f64>,
    minor: Vec<f64>,
}

impl Axis {
    /// An axis over `values` (already filtered to what the scale can show)
    /// with a little room beyond them, so markers at the ends are whole.
    /// `zero` makes a linear axis start at zero, for quantities whose size
    /// matters, not only their differences.
    fn fit(values: impl Iterator<Item = f64>, log: bool, zero: bool, max_ticks: usize) -> Axis {
        let (lo, hi) = values.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
        // No data: an empty axis of any sensible range will do.
        let (lo, hi) = if lo > hi { (1.0, 10.0) } else { (lo, hi) };
        if log {
            Axis::fit_log(lo, hi, max_ticks)
        } else {
            Axis::fit_linear(lo, hi, zero, max_ticks)
        }
    }

    fn fit_log(lo: f64, hi: f64, max_ticks: usize) -> Axis {
        let (lo, hi) = if hi == lo {
            (lo / 2.0, hi * 2.0)
        } else {
            (lo, hi)
        };
        // Five per cent of the span in log space, at least 10 per cent.
        let pad = (hi / lo).powf(0.05).max(1.1);
        let (lo, hi) = (lo / pad, hi * pad);
        Axis {
            lo,
            hi,
            log: true,
            ticks: ticks::log(lo, hi, max_ticks),
            minor: ticks::log_minor(lo, hi),
        }
    }

    fn fit_linear(lo: f64, hi: f64, zero: bool, max_ticks: usize) -> Axis {
        let from_zero = zero && lo >= 0.0;
        let (lo, hi) = if hi == lo {
            let d = (lo.abs() / 2.0).max(1.0);
            (if from_zero { 0.0 } else { lo - d }, hi + d)
        } else {
            (lo, hi)
        };
        let pad = (hi - lo) * 0.05;
        let (lo, hi) = if from_zero {
            (0.0, hi + pad)
        } else {
            (lo - pad, hi + pad)
        };
        Axis {
            lo,
            hi,
            log: false,
            ticks: ticks::linear(lo, hi, max_ticks),
            minor: Vec::new(),
        }
    }

    /// An axis with as many labelled ticks as fit along its `room` pixels,
    /// at most twelve; `across` for an x axis, whose labels sit side by
    /// side, else they are stacked.
    fn fit_room(values: &[f64], log: bool, zero: bool, room: i32, across: bool) -> Axis {
        let fit = |max| Axis::fit(values.iter().copied(), log, zero, max);
        // Tick choices are not nested (1-2-5 against 1-3 a decade), so every
        // limit is tried and the most ticks that fit win.
        (4..=12)
            .map(fit)
            .filter(|a| a.labels_fit(room, across))
            .max_by_key(|a| a.ticks.len())
            .unwrap_or_else(|| fit(3))
    }

    /// Whether every pair of neighbouring tick labels has room between
    /// them on an axis `room` pixels long: a gap of two or three characters
    /// side by side, half a line stacked. (Log ticks are unevenly spaced, so
    /// the pairs are checked one by one.)
    fn labels_fit(&self, room: i32, across: bool) -> bool {
        let along = |v: f64| {
            let f = if self.log {
                (v / self.lo).ln() / (self.hi / self.lo).ln()
            } else {
                (v - self.lo) / (self.hi - self.lo)
            };
            f * room as f64
        };
        let need = |a: f64, b: f64| {
            let (wa, h) = text_size(&ticks::label(a), px(TICK));
            let wb = text_size(&ticks::label(b), px(TICK)).0;
            if across {
                (wa + wb) as f64 / 2.0 + 20.0
            } else {
                h as f64 * 1.5
            }
        };
        self.ticks
            .windows(2)
            .all(|w| along(w[1]) - along(w[0]) >= need(w[0], w[1]))
    }

    /// The axis as plotters takes it.
    fn coord(&self) -> Ticked {
        let range = self.lo..self.hi;
        Ticked {
            scale: if self.log {
                Mapping::Log(range.log_scale().into())
            } else {
                Mapping::Linear(range.into())
            },
            ticks: self.ticks.clone(),
            minor: self.minor.clone(),
        }
    }

    /// The width in pixels of the widest tick label.
    fn label_width(&self) -> i32 {
        self.ticks
            .iter()
            .map(|&v| text_size(&ticks::label(v), px(TICK)).0)
            .max()
            .unwrap_or(0)
    }
}

/// A plotters axis whose ticks are chosen here rather than by plotters.
/// (plotters' own `WithKeyPoints` drops the formatting the mesh needs, and
/// one type for linear and log axes spares a copy of the drawing code for
/// each combination.)
struct Ticked {
    scale: Mapping,
    ticks: Vec<f64>,
    minor: Vec<f64>,
}

enum Mapping {
    Linear(RangedCoordf64),
    Log(LogCoord<f64>),
}

impl Ranged for Ticked {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        match &self.scale {
            Mapping::Linear(c) => c.map(value, limit),
            Mapping::Log(c) => c.map(value, limit),
        }
    }

    /// Labelled ticks for bold grid lines, the rest for light ones.
    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        match &self.scale {
            Mapping::Linear(c) => c.range(),
            Mapping::Log(c) => c.range(),
        }
    }
}

/// Every chart's coordinates.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<Ticked, Ticked>>;

/// How a legend entry shows its series.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Swatch {
    Line,
    Bar,
}

/// A legend drawn by hand rather than by plotters, so that its size is known
/// before it is placed.
struct Legend {
    entries: Vec<(String, RGBColor)>,
    swatch: Swatch,
}

/// Legend padding, swatch length and the gap before the name, in pixels.
const LEGEND_PAD: i32 = 8;
const SWATCH: i32 = 24;
const SWATCH_GAP: i32 = 8;

impl Legend {
    fn new<'a>(names: impl Iterator<Item = &'a str>, swatch: Swatch) -> Legend {
        Legend {
            entries: names
                .enumerate()
                .map(|(i, n)| (n.to_string(), COLORS[i % COLORS.len()]))
                .collect(),
            swatch,
        }
    }

    fn line_height() -> i32 {
        (px(LEGEND) * 1.5).round() as i32
    }

    fn size(&self) -> (i32, i32) {
        let text = self
            .entries
            .iter()
            .map(|(n, _)| text_size(n, px(LEGEND)).0)
            .max()
            .unwrap_or(0);
        (
            2 * LEGEND_PAD + SWATCH + SWATCH_GAP + text,
            2 * LEGEND_PAD + self.entries.len() as i32 * Self::line_height(),
        )
    }

    fn draw(&self, root: &DrawingArea<SVGBackend<'_>, Shift>, at: Px) -> anyhow::Result<()> {
        if self.entries.is_empty() {
            return Ok(());
        }
        let r = Rect::at(at, self.size());
        root.draw(&Rectangle::new(
            [(r.x0, r.y0), (r.x1, r.y1)],
            WHITE.mix(0.9).filled(),
        ))
        .map_err(err)?;
        root.draw(&Rectangle::new(
            [(r.x0, r.y0), (r.x1, r.y1)],
            BLACK.mix(0.4),
        ))
        .map_err(err)?;
        for (i, (name, c)) in self.entries.iter().enumerate() {
            let y = r.y0 + LEGEND_PAD + Self::line_height() * i as i32 + Self::line_height() / 2;
            let x = r.x0 + LEGEND_PAD;
            self.draw_swatch(root, (x, y), *c)?;
            let style = TextStyle::from((FONT, LEGEND).into_font())
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center));
            root.draw(&Text::new(
                name.clone(),
                (x + SWATCH + SWATCH_GAP, y),
                style,
            ))
            .map_err(err)?;
        }
        Ok(())
    }

    /// A short line with a marker, or a block, centred on `y`.
    fn draw_swatch(
        &self,
        root: &DrawingArea<SVGBackend<'_>, Shift>,
        (x, y): Px,
        c: RGBColor,
    ) -> anyhow::Result<()> {
        match self.swatch {
            Swatch::Line => {
                root.draw(&PathElement::new(
                    vec![(x, y), (x + SWATCH, y)],
                    c.stroke_width(2),
                ))
                .map_err(err)?;
                root.draw(&Circle::new((x + SWATCH / 2, y), 3, c.filled()))
                    .map_err(err)
            }
            Swatch::Bar => root
                .draw(&Rectangle::new(
                    [(x + 4, y - 6), (x + SWATCH - 4, y + 6)],
                    c.filled(),
                ))
                .map_err(err),
        }
    }
}

/// One attempt at a chart: the SVG text, and whether the legend found room
/// inside the plot (always so when it was put beside it).
struct Drawn {
    svg: String,
    legend_fits: bool,
}

/// Draw with the legend inside the plot; if every place there would cover
/// data, draw again on a wider canvas with the legend to the right.
fn draw_with_legend(
    path: &Path,
    draw: impl Fn(bool) -> anyhow::Result<Drawn>,
) -> anyhow::Result<()> {
    let mut drawn = draw(false)?;
    if !drawn.legend_fits {
        drawn = draw(true)?;
    }
    std::fs::write(path, drawn.svg).map_err(|e| err(format!("{}: {e}", path.display())))
}

/// The legend's place: beside the plot when `outside`, else a free corner.
fn place_legend(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    legend: &Legend,
    plot: &Rect,
    obstacles: &Obstacles,
    outside: bool,
) -> anyhow::Result<bool> {
    let at = if outside {
        Some((plot.x1 + 16, plot.y0))
    } else {
        layout::free_corner(plot, legend.size(), obstacles).map(|r| (r.x0, r.y0))
    };
    match at {
        Some(at) => legend.draw(root, at).map(|_| true),
        None => Ok(false),
    }
}

/// The canvas, wide enough for the legend when it goes beside the plot.
fn canvas(legend: &Legend, outside: bool) -> ((u32, u32), i32) {
    let extra = if outside { legend.size().0 + 16 } else { 0 };
    ((SIZE.0 + extra as u32, SIZE.1), extra)
}

/// The plot area of a chart in pixels.
fn plot_rect(chart: &Chart<'_, '_>) -> Rect {
    let (xs, ys) = chart.plotting_area().get_pixel_range();
    Rect {
        x0: xs.start,
        y0: ys.start,
        x1: xs.end,
        y1: ys.end,
    }
}

/// Grid, ticks and axis titles.
fn mesh(
    chart: &mut Chart<'_, '_>,
    x_desc: &str,
    y_desc: &str,
    x_format: &dyn Fn(&f64) -> String,
    x_grid: bool,
) -> anyhow::Result<()> {
    let y_format = |v: &f64| ticks::label(*v);
    let mut m = chart.configure_mesh();
    m.x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(x_format)
        .y_label_formatter(&y_format)
        .label_style((FONT, TICK))
        .axis_desc_style((FONT, AXIS))
        .bold_line_style(BLACK.mix(0.15))
        .light_line_style(BLACK.mix(0.05));
    if !x_grid {
        m.disable_x_mesh();
    }
    m.draw().map_err(err)
}

/// A line chart with markers.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    scale: Scale,
) -> anyhow::Result<()> {
    let chart = LineChart {
        title,
        x_label,
        y_label,
        series,
        log_x: scale == Scale::LogLog,
        log_y: scale != Scale::Linear,
    };
    draw_with_legend(path, |outside| chart.draw(outside))
}

struct LineChart<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    series: &'a [Series],
    log_x: bool,
    log_y: bool,
}

impl LineChart<'_> {
    fn draw(&self, outside: bool) -> anyhow::Result<Drawn> {
        let legend = Legend::new(self.series.iter().map(|s| s.name.as_str()), Swatch::Line);
        let (size, extra) = canvas(&legend, outside);
        let points: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| s.drawable(self.log_x, self.log_y))
            .map(|(p, _)| p)
            .collect();
        let xs: Vec<f64> = points.iter().map(|p| p.0).collect();
        let ys: Vec<f64> = points.iter().map(|p| p.1).collect();
        let x = Axis::fit_room(&xs, self.log_x, false, X_ROOM, true);
        let y = Axis::fit_room(&ys, self.log_y, true, Y_ROOM, false);
        let mut svg = String::new();
        let legend_fits = {
            let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
            root.fill(&WHITE).map_err(err)?;
            let mut b = ChartBuilder::on(&root);
            b.caption(self.title, (FONT, CAPTION))
                .margin(14)
                .margin_right(14 + extra)
                .x_label_area_size(52)
                .y_label_area_size(y.label_width() + 40);
            let chart = b.build_cartesian_2d(x.coord(), y.coord()).map_err(err)?;
            let fits = self.plot(chart, &root, &legend, outside)?;
            root.present().map_err(err)?;
            fits
        };
        Ok(Drawn { svg, legend_fits })
    }

    /// Everything inside the axes; whether the legend found its place.
    fn plot(
        &self,
        mut chart: Chart<'_, '_>,
        root: &DrawingArea<SVGBackend<'_>, Shift>,
        legend: &Legend,
        outside: bool,
    ) -> anyhow::Result<bool> {
        let x_format = |v: &f64| ticks::label(*v);
        mesh(&mut chart, self.x_label, self.y_label, &x_format, true)?;
        let mut obstacles = Obstacles::default();
        let mut labels = Vec::new();
        for (i, s) in self.series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            let texts = self.draw_series(&mut chart, s, c, &mut obstacles)?;
            labels.extend(texts.into_iter().map(|(p, t)| (p, t, c)));
        }
        let plot = plot_rect(&chart);
        let labels = place_point_labels(&plot, &mut obstacles, labels);
        draw_point_labels(root, &labels)?;
        place_legend(root, legend, &plot, &obstacles, outside)
    }

    /// One series' line and markers, which labels and the legend must then
    /// avoid; returns its point labels and where their points are.
    fn draw_series(
        &self,
        chart: &mut Chart<'_, '_>,
        s: &Series,
        c: RGBColor,
        obstacles: &mut Obstacles,
    ) -> anyhow::Result<Vec<(Px, String)>> {
        let pts = s.drawable(self.log_x, self.log_y);
        let xy: Vec<(f64, f64)> = pts.iter().map(|p| p.0).collect();
        chart
            .draw_series(LineSeries::new(xy.clone(), c.stroke_width(2)))
            .map_err(err)?;
        chart
            .draw_series(xy.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(err)?;
        let pixels: Vec<Px> = xy.iter().map(|p| chart.backend_coord(p)).collect();
        obstacles.marks.extend(
            pixels
                .iter()
                .map(|&(x, y)| Rect::spanning((x - 4, y - 4), (x + 4, y + 4))),
        );
        obstacles
            .segments
            .extend(pixels.windows(2).map(|w| (w[0], w[1])));
        let texts: Vec<&str> = pts.iter().map(|p| p.1).collect();
        Ok(merge_coincident(&pixels, &texts))
    }
}

/// Labels of points that fall on (nearly) the same pixel, joined, so that
/// settings with equal results read "depth 4, depth 5" rather than two
/// labels fighting for one place.
fn merge_coincident(pixels: &[Px], texts: &[&str]) -> Vec<(Px, String)> {
    let mut out: Vec<(Px, String)> = Vec::new();
    for (&p, &t) in pixels.iter().zip(texts) {
        if t.is_empty() {
            continue;
        }
        let near = |q: &Px| (q.0 - p.0).abs() <= 3 && (q.1 - p.1).abs() <= 3;
        match out.iter_mut().find(|(q, _)| near(q)) {
            Some((_, s)) => {
                s.push_str(", ");
                s.push_str(t);
            }
            None => out.push((p, t.to_string())),
        }
    }
    out
}

/// A point's label and where it goes.
struct PointLabel {
    point: Px,
    text: String,
    color: RGBColor,
    placed: layout::Placed,
}

/// Places each label beside its marker where it covers least, one after
/// another so that later labels avoid earlier ones.
fn place_point_labels(
    plot: &Rect,
    obstacles: &mut Obstacles,
    labels: Vec<(Px, String, RGBColor)>,
) -> Vec<PointLabel> {
    labels
        .into_iter()
        .map(|(point, text, color)| {
            let size = text_size(&text, px(POINT));
            let placed = layout::place_label(point, size, plot, obstacles);
            obstacles.texts.push(placed.rect);
            if placed.leader {
                obstacles
                    .segments
                    .push((point, layout::nearest(&placed.rect, point)));
            }
            PointLabel {
                point,
                text,
                color,
                placed,
            }
        })
        .collect()
}

/// Leaders, then labels. The labels have no backing: one would hide the
/// lines it crosses, and placement already keeps them off the data.
fn draw_point_labels(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    labels: &[PointLabel],
) -> anyhow::Result<()> {
    for l in labels.iter().filter(|l| l.placed.leader) {
        let end = layout::nearest(&l.placed.rect, l.point);
        root.draw(&PathElement::new(
            vec![l.point, end],
            l.color.stroke_width(1),
        ))
        .map_err(err)?;
    }
    for l in labels {
        let (h, x) = anchor(&l.placed.rect, l.point);
        let ink = darker(l.color);
        let style = TextStyle::from((FONT, POINT).into_font())
            .color(&ink)
            .pos(Pos::new(h, VPos::Center));
        let y = (l.placed.rect.y0 + l.placed.rect.y1) / 2;
        root.draw(&Text::new(l.text.clone(), (x, y), style))
            .map_err(err)?;
    }
    Ok(())
}

/// Text is aligned to the side of its box nearest its point, so that when
/// the estimated width is wider than the real text, the slack falls away
/// from the point rather than between the two.
fn anchor(r: &Rect, p: Px) -> (HPos, i32) {
    if r.x0 >= p.0 {
        (HPos::Left, r.x0)
    } else if r.x1 <= p.0 {
        (HPos::Right, r.x1)
    } else {
        (HPos::Center, (r.x0 + r.x1) / 2)
    }
}

/// The series colour, darkened so that small text in it stays legible.
fn darker(c: RGBColor) -> RGBColor {
    let d = |v: u8| (v as f64 * 0.75) as u8;
    RGBColor(d(c.0), d(c.1), d(c.2))
}

/// Grouped bars: one group per category, one bar per series.
pub fn bars(
    path: &Path,
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
) -> anyhow::Result<()> {
    let chart = BarChart {
        title,
        y_label,
        categories,
        series,
    };
    draw_with_legend(path, |outside| chart.draw(outside))
}

struct BarChart<'a> {
    title: &'a str,
    y_label: &'a str,
    categories: &'a [String],
    series: &'a [(String, Vec<f64>)],
}

impl BarChart<'_> {
    fn draw(&self, outside: bool) -> anyhow::Result<Drawn> {
        let legend = Legend::new(self.series.iter().map(|s| s.0.as_str()), Swatch::Bar);
        let (size, extra) = canvas(&legend, outside);
        let values = self
            .series
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .filter(|v| v.is_finite());
        let values: Vec<f64> = values.chain([0.0]).collect();
        let y = Axis::fit_room(&values, false, true, Y_ROOM, false);
        let n = self.categories.len().max(1);
        // One labelled tick under the middle of each group.
        let x = Ticked {
            scale: Mapping::Linear((0.0..n as f64).into()),
            ticks: (0..n).map(|i| i as f64 + 0.5).collect(),
            minor: Vec::new(),
        };
        let mut svg = String::new();
        let legend_fits = {
            let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
            root.fill(&WHITE).map_err(err)?;
            let mut chart = ChartBuilder::on(&root)
                .caption(self.title, (FONT, CAPTION))
                .margin(14)
                .margin_right(14 + extra)
                .x_label_area_size(40)
                .y_label_area_size(y.label_width() + 40)
                .build_cartesian_2d(x, y.coord())
                .map_err(err)?;
            let x_format = |x: &f64| {
                let i = x.floor();
                (i >= 0.0)
                    .then(|| self.categories.get(i as usize))
                    .flatten()
                    .cloned()
                    .unwrap_or_default()
            };
            mesh(&mut chart, "", self.y_label, &x_format, false)?;
            let mut obstacles = Obstacles::default();
            self.draw_bars(&mut chart, &mut obstacles)?;
            let plot = plot_rect(&chart);
            let fits = place_legend(&root, &legend, &plot, &obstacles, outside)?;
            root.present().map_err(err)?;
            fits
        };
        Ok(Drawn { svg, legend_fits })
    }

    /// The bars, each also an obstacle for the legend.
    fn draw_bars(
        &self,
        chart: &mut Chart<'_, '_>,
        obstacles: &mut Obstacles,
    ) -> anyhow::Result<()> {
        let w = 0.8 / self.series.len().max(1) as f64;
        for (si, (_, vals)) in self.series.iter().enumerate() {
            let c = COLORS[si % COLORS.len()];
            let bars: Vec<[(f64, f64); 2]> = vals
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
                .map(|(ci, &v)| {
                    let x = ci as f64 + 0.1 + si as f64 * w;
                    [(x, 0.0), (x + w * 0.95, v)]
                })
                .collect();
            chart
                .draw_series(bars.iter().map(|&b| Rectangle::new(b, c.filled())))
                .map_err(err)?;
            obstacles.marks.extend(
                bars.iter()
                    .map(|[a, b]| Rect::spanning(chart.backend_coord(a), chart.backend_coord(b))),
            );
            let missing: Vec<f64> = vals
                .iter()
                .enumerate()
                .filter(|(_, v)| !v.is_finite())
                .map(|(ci, _)| ci as f64 + 0.1 + (si as f64 + 0.475) * w)
                .collect();
            mark_missing(chart, &missing, obstacles)?;
        }
        Ok(())
    }
}

/// "n/a" above the axis at each `x` where a bar is missing, so that it
/// does not pass for a zero.
fn mark_missing(
    chart: &mut Chart<'_, '_>,
    xs: &[f64],
    obstacles: &mut Obstacles,
) -> anyhow::Result<()> {
    let grey = BLACK.mix(0.6);
    let style = TextStyle::from((FONT, POINT).into_font())
        .color(&grey)
        .pos(Pos::new(HPos::Center, VPos::Bottom));
    chart
        .draw_series(
            xs.iter()
                .map(|&x| EmptyElement::at((x, 0.0)) + Text::new("n/a", (0, -3), style.clone())),
        )
        .map_err(err)?;
    let (tw, th) = text_size("n/a", px(POINT));
    obstacles.texts.extend(xs.iter().map(|&x| {
        let (cx, cy) = chart.backend_coord(&(x, 0.0));
        Rect::at((cx - tw / 2, cy - 3 - th), (tw, th))
    }));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Where sample charts go: `SRAY_CHART_SAMPLES` keeps them for viewing
    /// (e.g. with rsvg-convert), otherwise a temporary directory.
    fn sample_dir() -> (Option<tempfile::TempDir>, std::path::PathBuf) {
        match std::env::var_os("SRAY_CHART_SAMPLES") {
            Some(d) => {
                let d = std::path::PathBuf::from(d);
                std::fs::create_dir_all(&d).expect("sample directory");
                (None, d)
            }
            None => {
                let t = tempfile::tempdir().expect("temporary directory");
                let d = t.path().to_path_buf();
                (Some(t), d)
            }
        }
    }

    /// The text of every `<text>` element, in order.
    fn texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let body = t.split_once('>')?.1;
                Some(body.split_once("</text>")?.0.trim().to_string())
            })
            .collect()
    }

    fn speed_accuracy() -> Vec<Series> {
        let depth = Series::new(
            "depth",
            vec![
                (0.020, 0.081),
                (0.026, 0.034),
                (0.031, 0.019),
                (0.034, 0.0185),
                (0.0342, 0.0184),
            ],
        )
        .with_labels((1..=5).map(|d| format!("depth {d}")).collect());
        let precision = Series::new("precision", vec![(0.0305, 0.0186), (0.0336, 0.0184)])
            .with_labels(vec!["single".into(), "double".into()]);
        let samples = Series::new(
            "samples",
            vec![(0.034, 0.0184), (0.12, 0.0071), (0.47, 0.0032)],
        )
        .with_labels(vec!["corners".into(), "4 spp".into(), "16 spp".into()]);
        vec![depth, precision, samples]
    }

    #[test]
    fn speed_accuracy_chart_labels_ticks_and_points() {
        let (_keep, dir) = sample_dir();
        let path = dir.join("speed_accuracy.svg");
        lines(
            &path,
            "balls2: time against error",
            "seconds",
            "RMS error from the reference",
            &speed_accuracy(),
            Scale::LogLog,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        for want in [
            "depth 1", "depth 3", "single", "double", "16 spp", "corners", "0.01", "0.05",
        ] {
            assert!(t.iter().any(|s| s == want), "no {want:?} in {t:?}");
        }
        // No tick reads like a float dump.
        assert!(!t.iter().any(|s| s.ends_with(".0")), "{t:?}");
        // Several labelled ticks on the log axis (0.005 to 0.08 and beyond).
        let y_ticks = t.iter().filter(|s| s.starts_with("0.0")).count();
        assert!(y_ticks >= 3, "{t:?}");
    }

    #[test]
    fn log_log_chart_groups_thousands() {
        let (_keep, dir) = sample_dir();
        let path = dir.join("loglog.svg");
        let sizes = [1_000.0, 10_000.0, 100_000.0, 1_000_000.0];
        let df = Series::new("df total", sizes.iter().map(|&n| (n, n * 2e-5)).collect());
        let bf = Series::new(
            "bf total",
            sizes.iter().map(|&n| (n, n * 3e-5 + 0.5)).collect(),
        );
        let pre = Series::new(
            "df preprocess",
            sizes.iter().map(|&n| (n, n * 4e-6)).collect(),
        );
        lines(
            &path,
            "tetra: time against objects",
            "objects",
            "seconds",
            &[df, bf, pre],
            Scale::LogLog,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        for want in [
            "1,000",
            "10,000",
            "100,000",
            "1,000,000",
            "df total",
            "bf total",
        ] {
            assert!(t.iter().any(|s| s == want), "no {want:?} in {t:?}");
        }
        let numeric = |s: &&String| s.starts_with(|c: char| c.is_ascii_digit());
        assert!(
            !t.iter()
                .filter(numeric)
                .any(|s| s.ends_with(".0") || s.contains('e')),
            "{t:?}"
        );
    }

    #[test]
    fn linear_and_log_y_charts_draw() {
        let (_keep, dir) = sample_dir();
        // Remaining rays per pass: falls by orders of magnitude.
        let rays: Vec<Series> = [(8, 1), (8, 4), (16, 1), (16, 4)]
            .iter()
            .enumerate()
            .map(|(i, &(res, store))| {
                let pts = (1..=9)
                    .map(|p| (p as f64, 65536.0 * (0.35 + 0.05 * i as f64).powi(p - 1)))
                    .collect();
                Series::new(format!("{res}^3, store {store}"), pts)
            })
            .collect();
        let path = dir.join("log_y.svg");
        lines(
            &path,
            "Unfinished eye rays at each pass (rings)",
            "pass",
            "remaining rays",
            &rays,
            Scale::LogY,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        assert!(
            t.iter()
                .any(|s| s == "65,536" || s == "50,000" || s == "10,000"),
            "{t:?}"
        );
        let path = dir.join("linear.svg");
        lines(
            &path,
            "Remaining rays (linear)",
            "pass",
            "remaining rays",
            &rays,
            Scale::Linear,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        assert!(t.iter().any(|s| s == "60,000"), "{t:?}");
        assert!(t.iter().any(|s| s == "8^3, store 4"), "{t:?}");
    }

    #[test]
    fn bar_chart_names_categories_and_series() {
        let (_keep, dir) = sample_dir();
        let path = dir.join("bars.svg");
        let cats: Vec<String> = ["balls3", "gears3", "rings5", "tetra6", "tree10"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let series = vec![
            ("depth-first".to_string(), vec![1.2, 3.4, 12.5, 0.8, 2.2]),
            (
                "breadth-first".to_string(),
                vec![1.9, 4.1, 11.0, f64::NAN, 3.0],
            ),
        ];
        bars(
            &path,
            "Total render time, 256x256, one thread",
            "seconds",
            &cats,
            &series,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        for want in [
            "balls3",
            "tree10",
            "depth-first",
            "breadth-first",
            "10",
            "0",
            "n/a",
        ] {
            assert!(t.iter().any(|s| s == want), "no {want:?} in {t:?}");
        }
    }

    #[test]
    fn legend_goes_beside_the_plot_when_every_corner_has_data() {
        let (_keep, dir) = sample_dir();
        let path = dir.join("legend_beside.svg");
        // Tall bars at both ends and in the middle, all starting at zero:
        // no corner or middle of the plot is free.
        let cats: Vec<String> = (1..=5).map(|i| format!("scene{i}")).collect();
        let series = vec![
            ("sray".to_string(), vec![9.0, 2.0, 9.5, 2.0, 9.0]),
            ("POV-Ray".to_string(), vec![9.2, 1.0, 9.7, 1.5, 9.4]),
            ("RayShade".to_string(), vec![8.8, 1.2, 9.9, 1.1, 9.6]),
        ];
        bars(&path, "Whole-process time", "seconds", &cats, &series).expect("chart");
        let svg = std::fs::read_to_string(&path).expect("svg");
        let width: u32 = svg
            .split_once("width=\"")
            .and_then(|(_, rest)| rest.split_once('"'))
            .and_then(|(w, _)| w.parse().ok())
            .expect("svg width");
        assert!(width > SIZE.0, "legend inside: width {width}");
        assert!(texts(&svg).iter().any(|s| s == "RayShade"));
    }

    #[test]
    fn narrow_ranges_still_get_several_ticks() {
        // `--quick` runs: every render takes about the same 10 ms.
        let (_keep, dir) = sample_dir();
        let path = dir.join("speed_accuracy_quick.svg");
        let depth = Series::new(
            "maximum depth",
            vec![
                (0.0101, 0.094),
                (0.0104, 0.051),
                (0.0108, 0.047),
                (0.0111, 0.047),
                (0.0112, 0.047),
            ],
        )
        .with_labels((1..=5).map(|d| format!("depth {d}")).collect());
        let precision = Series::new("precision", vec![(0.0110, 0.047), (0.0113, 0.047)])
            .with_labels(vec!["single".into(), "double".into()]);
        let samples = Series::new(
            "samples per pixel",
            vec![(0.0112, 0.047), (0.0118, 0.031), (0.0125, 0.024)],
        )
        .with_labels(vec!["corners".into(), "4 spp".into(), "16 spp".into()]);
        lines(
            &path,
            "balls1: time against error",
            "seconds",
            "RMS error from the reference",
            &[depth, precision, samples],
            Scale::LogLog,
        )
        .expect("chart");
        let t = texts(&std::fs::read_to_string(&path).expect("svg"));
        let x_ticks = t.iter().filter(|s| s.starts_with("0.01")).count();
        assert!(x_ticks >= 3, "{t:?}");
        for want in [
            "depth 3", "depth 5", "single", "double", "corners", "16 spp",
        ] {
            assert!(t.iter().any(|s| s == want), "no {want:?} in {t:?}");
        }
        // The error axis spans less than a decade and still reads.
        let y_ticks = t.iter().filter(|s| s.starts_with("0.0")).count() - x_ticks;
        assert!(y_ticks >= 3, "{t:?}");
    }
}
