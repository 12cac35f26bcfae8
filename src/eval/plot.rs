//! A small line chart drawn straight into an [`RgbRaster`], for the benchmark's PNG.
//!
//! No plotting crate: the ones that draw text need system fonts or a bundled font file, and the
//! chart needs only axes, ticks, polylines, markers and short labels. Text uses a built-in 5×7
//! pixel font (upper-case letters, digits and a few signs; lower case is drawn as upper case).

use crate::raster::{Rgb, RgbRaster};

/// One polyline with markers.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Line and marker colour.
    pub colour: Rgb,
    /// Points `(x, y)` in data units, drawn in order; each may carry a short label drawn beside
    /// its marker.
    pub points: Vec<(f64, f64, String)>,
}

/// A chart with a logarithmic or linear x axis and a linear y axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Label under the x axis.
    pub x_label: String,
    /// Label left of the y axis (drawn above it).
    pub y_label: String,
    /// Logarithmic x axis (base 10).
    pub x_log: bool,
    /// The series.
    pub series: Vec<Series>,
}

/// A palette of distinguishable colours for series.
pub const PALETTE: [Rgb; 6] = [
    [0.12, 0.47, 0.71],
    [1.0, 0.5, 0.05],
    [0.17, 0.63, 0.17],
    [0.84, 0.15, 0.16],
    [0.58, 0.4, 0.74],
    [0.55, 0.34, 0.29],
];

const GLYPH_W: usize = 5;
const GLYPH_H: usize = 7;

/// The 5×7 glyph of `c` (rows top to bottom, bit 4 = leftmost column); unknown characters draw
/// as a box.
fn glyph(c: char) -> [u8; GLYPH_H] {
    let rows: [&str; GLYPH_H] = match c.to_ascii_uppercase() {
        ' ' => [
            ".....", ".....", ".....", ".....", ".....", ".....", ".....",
        ],
        '0' => [
            ".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###.",
        ],
        '1' => [
            "..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###.",
        ],
        '2' => [
            ".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####",
        ],
        '3' => [
            "#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###.",
        ],
        '4' => [
            "...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#.",
        ],
        '5' => [
            "#####", "#....", "####.", "....#", "....#", "#...#", ".###.",
        ],
        '6' => [
            "..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###.",
        ],
        '7' => [
            "#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#...",
        ],
        '8' => [
            ".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###.",
        ],
        '9' => [
            ".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##..",
        ],
        'A' => [
            ".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#",
        ],
        'B' => [
            "####.", "#...#", "#...#", "####.", "#...#", "#...#", "####.",
        ],
        'C' => [
            ".###.", "#...#", "#....", "#....", "#....", "#...#", ".###.",
        ],
        'D' => [
            "###..", "#..#.", "#...#", "#...#", "#...#", "#..#.", "###..",
        ],
        'E' => [
            "#####", "#....", "#....", "####.", "#....", "#....", "#####",
        ],
        'F' => [
            "#####", "#....", "#....", "####.", "#....", "#....", "#....",
        ],
        'G' => [
            ".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".####",
        ],
        'H' => [
            "#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#",
        ],
        'I' => [
            ".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###.",
        ],
        'J' => [
            "..###", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##..",
        ],
        'K' => [
            "#...#", "#..#.", "#.#..", "##...", "#.#..", "#..#.", "#...#",
        ],
        'L' => [
            "#....", "#....", "#....", "#....", "#....", "#....", "#####",
        ],
        'M' => [
            "#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#",
        ],
        'N' => [
            "#...#", "#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#",
        ],
        'O' => [
            ".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.",
        ],
        'P' => [
            "####.", "#...#", "#...#", "####.", "#....", "#....", "#....",
        ],
        'Q' => [
            ".###.", "#...#", "#...#", "#...#", "#.#.#", "#..#.", ".##.#",
        ],
        'R' => [
            "####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#",
        ],
        'S' => [
            ".####", "#....", "#....", ".###.", "....#", "....#", "####.",
        ],
        'T' => [
            "#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#..",
        ],
        'U' => [
            "#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.",
        ],
        'V' => [
            "#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#..",
        ],
        'W' => [
            "#...#", "#...#", "#...#", "#.#.#", "#.#.#", "#.#.#", ".#.#.",
        ],
        'X' => [
            "#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#",
        ],
        'Y' => [
            "#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#..",
        ],
        'Z' => [
            "#####", "....#", "...#.", "..#..", ".#...", "#....", "#####",
        ],
        '.' => [
            ".....", ".....", ".....", ".....", ".....", ".##..", ".##..",
        ],
        ',' => [
            ".....", ".....", ".....", ".....", ".##..", "..#..", ".#...",
        ],
        '-' => [
            ".....", ".....", ".....", "#####", ".....", ".....", ".....",
        ],
        '+' => [
            ".....", "..#..", "..#..", "#####", "..#..", "..#..", ".....",
        ],
        '=' => [
            ".....", ".....", "#####", ".....", "#####", ".....", ".....",
        ],
        '(' => [
            "...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#.",
        ],
        ')' => [
            ".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#...",
        ],
        '/' => [
            ".....", "....#", "...#.", "..#..", ".#...", "#....", ".....",
        ],
        ':' => [
            ".....", ".##..", ".##..", ".....", ".##..", ".##..", ".....",
        ],
        '%' => [
            "##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##",
        ],
        '_' => [
            ".....", ".....", ".....", ".....", ".....", ".....", "#####",
        ],
        '×' => [
            ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", ".....",
        ],
        _ => [
            "#####", "#...#", "#...#", "#...#", "#...#", "#...#", "#####",
        ],
    };
    let mut out = [0u8; GLYPH_H];
    for (o, row) in out.iter_mut().zip(rows) {
        for (i, b) in row.bytes().enumerate() {
            if b == b'#' {
                *o |= 1 << (GLYPH_W - 1 - i);
            }
        }
    }
    out
}

/// A canvas with drawing primitives.
struct Canvas {
    image: RgbRaster,
}

impl Canvas {
    fn put(&mut self, x: i64, y: i64, c: Rgb) {
        let (w, h) = self.image.size();
        if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
            self.image.set(x as usize, y as usize, c);
        }
    }

    fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.put(x, y, c);
            }
        }
    }

    /// A line `thickness` pixels wide (Bresenham with a square brush).
    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), thickness: i64, c: Rgb) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        let lo = -(thickness - 1) / 2;
        let hi = thickness / 2;
        loop {
            self.rect(x + lo, y + lo, x + hi, y + hi, c);
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// Text with its top-left corner at `(x, y)`, each font pixel `scale × scale`.
    fn text(&mut self, x: i64, y: i64, s: &str, scale: i64, c: Rgb) {
        for (i, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            let ox = x + i as i64 * (GLYPH_W as i64 + 1) * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..GLYPH_W {
                    if bits & (1 << (GLYPH_W - 1 - col)) != 0 {
                        let px = ox + col as i64 * scale;
                        let py = y + row as i64 * scale;
                        self.rect(px, py, px + scale - 1, py + scale - 1, c);
                    }
                }
            }
        }
    }
}

/// Width in pixels of `s` drawn at `scale`.
fn text_width(s: &str, scale: i64) -> i64 {
    s.chars().count() as i64 * (GLYPH_W as i64 + 1) * scale - scale
}

/// "Nice" tick values covering `[lo, hi]` (1, 2, 5 × 10^k steps), at most ~8.
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-9);
    let raw = span / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 8.0)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * step {
        out.push(t);
        t += step;
    }
    out
}

/// Decade ticks (1, 2, 5 × 10^k) inside `[lo, hi]` (positive).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let t = m * decade;
            if t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9) {
                out.push(t);
            }
        }
        decade *= 10.0;
    }
    out
}

/// Formats a tick value compactly.
fn tick_label(v: f64) -> String {
    if v.abs() >= 100.0 || v == v.round() {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').to_string()
    }
}

impl Chart {
    /// Draws the chart at `width × height` (at least 320×240).
    pub fn render(&self, width: usize, height: usize) -> RgbRaster {
        let (width, height) = (width.max(320), height.max(240));
        let mut cv = Canvas {
            image: RgbRaster::new(width, height, [1.0; 3]),
        };
        let black = [0.0; 3];
        let grey = [0.85; 3];
        let legend_w = self
            .series
            .iter()
            .map(|s| text_width(&s.name, 2) + 40)
            .max()
            .unwrap_or(0)
            .min(width as i64 / 3);
        let (left, right, top, bottom) = (
            80i64,
            width as i64 - 20 - legend_w,
            50i64,
            height as i64 - 60,
        );
        let finite: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| (p.0, p.1)))
            .filter(|(x, y)| x.is_finite() && y.is_finite() && (!self.x_log || *x > 0.0))
            .collect();
        cv.text(left, 15, &self.title, 2, black);
        if finite.is_empty() || right <= left + 20 || bottom <= top + 20 {
            cv.text(left, top + 20, "NO DATA", 2, black);
            return cv.image;
        }
        let fx = |x: f64| if self.x_log { x.log10() } else { x };
        let (mut x_lo, mut x_hi) = finite
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(fx(p.0)), b.max(fx(p.0)))
            });
        let (mut y_lo, mut y_hi) = finite
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.1), b.max(p.1))
            });
        let pad = |lo: &mut f64, hi: &mut f64, min_span: f64| {
            let span = (*hi - *lo).max(min_span);
            let mid = 0.5 * (*hi + *lo);
            *lo = mid - 0.55 * span;
            *hi = mid + 0.55 * span;
        };
        pad(&mut x_lo, &mut x_hi, if self.x_log { 0.5 } else { 1e-3 });
        pad(&mut y_lo, &mut y_hi, 1.0);
        let to_px = |x: f64, y: f64| -> (i64, i64) {
            let tx = (fx(x) - x_lo) / (x_hi - x_lo);
            let ty = (y - y_lo) / (y_hi - y_lo);
            (
                left + (tx * (right - left) as f64).round() as i64,
                bottom - (ty * (bottom - top) as f64).round() as i64,
            )
        };
        // Grid and ticks.
        let x_ticks = if self.x_log {
            log_ticks(10f64.powf(x_lo), 10f64.powf(x_hi))
        } else {
            linear_ticks(x_lo, x_hi)
        };
        for t in x_ticks {
            let (px, _) = to_px(t, y_lo);
            cv.line((px, top), (px, bottom), 1, grey);
            cv.line((px, bottom), (px, bottom + 5), 1, black);
            let label = tick_label(t);
            cv.text(px - text_width(&label, 1) / 2, bottom + 9, &label, 1, black);
        }
        for t in linear_ticks(y_lo, y_hi) {
            let (_, py) = to_px(10f64.powf(x_lo).max(f64::MIN_POSITIVE), t);
            cv.line((left, py), (right, py), 1, grey);
            cv.line((left - 5, py), (left, py), 1, black);
            let label = tick_label(t);
            cv.text(left - 9 - text_width(&label, 1), py - 3, &label, 1, black);
        }
        cv.line((left, top), (left, bottom), 2, black);
        cv.line((left, bottom), (right, bottom), 2, black);
        cv.text(
            (left + right) / 2 - text_width(&self.x_label, 2) / 2,
            bottom + 28,
            &self.x_label,
            2,
            black,
        );
        cv.text(10, top - 18, &self.y_label, 1, black);
        // Series.
        for s in &self.series {
            let pts: Vec<((i64, i64), &str)> = s
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite() && (!self.x_log || p.0 > 0.0))
                .map(|p| (to_px(p.0, p.1), p.2.as_str()))
                .collect();
            for pair in pts.windows(2) {
                cv.line(pair[0].0, pair[1].0, 2, s.colour);
            }
            for ((px, py), label) in &pts {
                cv.rect(px - 3, py - 3, px + 3, py + 3, s.colour);
                cv.text(px + 6, py - 10, label, 1, black);
            }
        }
        // Legend.
        let mut ly = top;
        for s in &self.series {
            let lx = right + 20;
            cv.rect(lx, ly + 3, lx + 16, ly + 9, s.colour);
            cv.text(lx + 24, ly, &s.name, 2, black);
            ly += 24;
        }
        cv.image
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice() {
        assert_eq!(linear_ticks(0.0, 10.0), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(log_ticks(0.3, 12.0), vec![0.5, 1.0, 2.0, 5.0, 10.0]);
        assert_eq!(tick_label(2.0), "2");
        assert_eq!(tick_label(0.5), "0.5");
        assert_eq!(tick_label(1.5), "1.5");
    }

    #[test]
    fn glyphs_have_ink_and_unknowns_draw_a_box() {
        for c in "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.-+()/:%".chars() {
            assert!(glyph(c).iter().any(|&r| r != 0), "{c}");
        }
        assert_eq!(glyph('a'), glyph('A'));
        assert_eq!(glyph('~')[0], 0b11111);
        assert!(glyph(' ').iter().all(|&r| r == 0));
    }

    #[test]
    fn chart_draws_series_in_their_colour() {
        let chart = Chart {
            title: "Quality vs time".into(),
            x_label: "seconds".into(),
            y_label: "PSNR dB".into(),
            x_log: true,
            series: vec![Series {
                name: "photo".into(),
                colour: PALETTE[3],
                points: vec![(1.0, 20.0, "D".into()), (10.0, 30.0, "F".into())],
            }],
        };
        let img = chart.render(400, 300);
        assert_eq!(img.size(), (400, 300));
        let red = img.data().iter().filter(|&&p| p == PALETTE[3]).count();
        assert!(red > 100, "{red}");
        // Nothing to plot: still an image, no panic.
        let empty = Chart {
            series: vec![],
            ..chart.clone()
        };
        assert_eq!(empty.render(10, 10).size(), (320, 240));
        let nan = Chart {
            series: vec![Series {
                points: vec![
                    (f64::NAN, 1.0, String::new()),
                    (0.0, f64::INFINITY, String::new()),
                ],
                ..chart.series[0].clone()
            }],
            ..chart
        };
        assert_eq!(nan.render(400, 300).size(), (400, 300));
    }
}
