//! PNG drawing for result pictures (docs/method.md §6): an RGB canvas with lines, rectangles and a built-in 5×7 bitmap
//! font, and a line plot with error bars (RMSE against K_x per method).

use std::io::Cursor;
use std::path::Path;

use any4d_data::io::write_atomic;
use image::{ImageFormat, Rgb, RgbImage};

use crate::error::{EvalError, Result};

/// Colours of successive series (colour-blind-safe Okabe–Ito order).
pub const PALETTE: [[u8; 3]; 7] = [
    [0, 114, 178],
    [213, 94, 0],
    [0, 158, 115],
    [204, 121, 167],
    [230, 159, 0],
    [86, 180, 233],
    [0, 0, 0],
];
pub const WHITE: [u8; 3] = [255, 255, 255];
pub const BLACK: [u8; 3] = [0, 0, 0];
pub const GREY: [u8; 3] = [200, 200, 200];

/// Glyph rows of the 5×7 font, bit 4 = leftmost column. Lower case is drawn with the upper-case glyphs.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        ' ' => [0; 7],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '*' => [0, 0x04, 0x15, 0x0E, 0x15, 0x04, 0],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '#' => [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A],
        '\'' => [0x04, 0x04, 0x08, 0, 0, 0, 0],
        '|' => [0x04; 7],
        '±' => [0x04, 0x04, 0x1F, 0x04, 0x04, 0, 0x1F],
        '×' => [0, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0, 0x04], // '?'
    }
}

/// Width in pixels of `text` drawn at `scale` (6 columns per character including spacing).
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * 6 * scale
}

/// An RGB image with clipped drawing primitives.
pub struct Canvas {
    pub img: RgbImage,
}

impl Canvas {
    /// A `width × height` canvas filled with `background`.
    pub fn new(width: u32, height: u32, background: [u8; 3]) -> Self {
        Self {
            img: RgbImage::from_pixel(width, height, Rgb(background)),
        }
    }

    /// Set one pixel; outside the canvas is ignored.
    pub fn put(&mut self, x: i64, y: i64, color: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.img.width() && (y as u32) < self.img.height() {
            self.img.put_pixel(x as u32, y as u32, Rgb(color));
        }
    }

    /// Filled rectangle with top-left (x, y).
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, color: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, color);
            }
        }
    }

    /// Rectangle outline.
    pub fn rect(&mut self, x: i64, y: i64, w: i64, h: i64, color: [u8; 3]) {
        self.line(x, y, x + w - 1, y, color, 1);
        self.line(x, y + h - 1, x + w - 1, y + h - 1, color, 1);
        self.line(x, y, x, y + h - 1, color, 1);
        self.line(x + w - 1, y, x + w - 1, y + h - 1, color, 1);
    }

    /// Bresenham line, `width` pixels thick (square pen).
    pub fn line(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, color: [u8; 3], width: i64) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        let half = (width - 1) / 2;
        loop {
            self.fill_rect(x - half, y - half, width, width, color);
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

    /// Draw `text` with its top-left corner at (x, y), each font pixel a `scale × scale` block.
    pub fn text(&mut self, x: i64, y: i64, text: &str, color: [u8; 3], scale: u32) {
        let s = i64::from(scale);
        for (i, c) in text.chars().enumerate() {
            let g = glyph(c);
            let ox = x + i as i64 * 6 * s;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        self.fill_rect(ox + col * s, y + row as i64 * s, s, s, color);
                    }
                }
            }
        }
    }

    /// Encode as PNG bytes.
    pub fn png_bytes(&self, path: &Path) -> Result<Vec<u8>> {
        let mut buf = Vec::new();
        self.img
            .write_to(&mut Cursor::new(&mut buf), ImageFormat::Png)
            .map_err(|e| EvalError::invalid(path, "png", e.to_string()))?;
        Ok(buf)
    }

    /// Write as PNG (temp file, then rename).
    pub fn save_png(&self, path: &Path) -> Result<()> {
        Ok(write_atomic(path, &self.png_bytes(path)?)?)
    }
}

/// One line of a plot: points (x, y) and optional ± half-widths (error bars).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub errors: Option<Vec<f64>>,
}

/// Axis tick values: about `target` "nice" steps (1, 2, 5 × 10^k) covering [lo, hi].
pub fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = (hi - lo).abs().max(1e-12);
    let raw = span / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).floor() * step;
    let mut ticks = Vec::new();
    let mut t = first;
    while t <= hi + step * 0.5 {
        ticks.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    ticks
}

fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    format!("{v:.decimals$}")
}

/// A line plot with markers, optional error bars and a legend, saved as PNG.
/// Errors: no series, no points, or non-finite values (named by series label).
/// The y axis starts at zero (or below, for negative values).
pub fn line_plot(title: &str, x_label: &str, y_label: &str, series: &[Series], path: &Path) -> Result<()> {
    canvas_line_plot(title, x_label, y_label, series, path)?.save_png(path)
}

/// As [`line_plot`], with the y axis fitted to the values instead of starting at zero (for log-scale values such
/// as loss curves, where zero means nothing).
pub fn line_plot_fit_y(title: &str, x_label: &str, y_label: &str, series: &[Series], path: &Path) -> Result<()> {
    plot_canvas(title, x_label, y_label, series, path, false)?.save_png(path)
}

/// As [`line_plot`], returning the canvas instead of writing it (`path` only names errors).
pub fn canvas_line_plot(title: &str, x_label: &str, y_label: &str, series: &[Series], path: &Path) -> Result<Canvas> {
    plot_canvas(title, x_label, y_label, series, path, true)
}

fn plot_canvas(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    path: &Path,
    y_from_zero: bool,
) -> Result<Canvas> {
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for s in series {
        for (i, &(x, y)) in s.points.iter().enumerate() {
            let e = s.errors.as_ref().and_then(|e| e.get(i)).copied().unwrap_or(0.0);
            if !(x.is_finite() && y.is_finite() && e.is_finite()) {
                return Err(EvalError::invalid(
                    path,
                    &s.label,
                    format!("point {i} = ({x}, {y} ± {e}) is not finite"),
                ));
            }
            xs.push(x);
            ys.extend([y - e, y + e]);
        }
    }
    if xs.is_empty() {
        return Err(EvalError::invalid(path, "series", "nothing to plot".to_string()));
    }
    let (w, h) = (720i64, 480i64);
    let (left, right, top, bottom) = (80i64, 200i64, 40i64, 60i64);
    let (pw, ph) = (w - left - right, h - top - bottom);
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init| v.iter().copied().fold(init, f);
    let (mut x0, mut x1) = (
        fold(&xs, f64::min, f64::INFINITY),
        fold(&xs, f64::max, f64::NEG_INFINITY),
    );
    let (mut y0, mut y1) = (
        fold(&ys, f64::min, f64::INFINITY).min(if y_from_zero { 0.0 } else { f64::INFINITY }),
        fold(&ys, f64::max, f64::NEG_INFINITY),
    );
    if x1 - x0 < 1e-12 {
        (x0, x1) = (x0 - 1.0, x1 + 1.0);
    }
    if y1 - y0 < 1e-12 {
        y1 = y0 + 1.0;
    }
    let pad = (x1 - x0) * 0.05;
    let (x0, x1) = (x0 - pad, x1 + pad);
    let yt = nice_ticks(y0, y1, 5);
    y0 = y0.min(yt[0]);
    y1 = y1.max(*yt.last().unwrap_or(&y1));
    let px = |x: f64| left + ((x - x0) / (x1 - x0) * pw as f64).round() as i64;
    let py = |y: f64| top + ph - ((y - y0) / (y1 - y0) * ph as f64).round() as i64;

    let mut c = Canvas::new(w as u32, h as u32, WHITE);
    c.text(left, 12, title, BLACK, 2);
    let ystep = if yt.len() > 1 { yt[1] - yt[0] } else { 1.0 };
    for &t in &yt {
        if t < y0 - 1e-12 || t > y1 + 1e-12 {
            continue;
        }
        c.line(left, py(t), left + pw, py(t), GREY, 1);
        let lab = tick_label(t, ystep);
        c.text(left - 8 - i64::from(text_width(&lab, 1)), py(t) - 3, &lab, BLACK, 1);
    }
    // Integer x values (such as K_x) get integer ticks; the x range is padded so end points clear the frame.
    let integer_x = xs.iter().all(|x| x.fract() == 0.0) && x1 - x0 <= 12.0;
    let xt = if integer_x {
        (x0 as i64..=x1 as i64).map(|t| t as f64).collect()
    } else {
        nice_ticks(x0, x1, 6)
    };
    let xstep = if xt.len() > 1 { xt[1] - xt[0] } else { 1.0 };
    for &t in xt.iter().filter(|t| **t >= x0 - 1e-12 && **t <= x1 + 1e-12) {
        c.line(px(t), top + ph, px(t), top + ph + 4, BLACK, 1);
        let lab = if integer_x {
            format!("{t:.0}")
        } else {
            tick_label(t, xstep)
        };
        c.text(px(t) - i64::from(text_width(&lab, 1)) / 2, top + ph + 8, &lab, BLACK, 1);
    }
    c.rect(left, top, pw + 1, ph + 1, BLACK);
    c.text(
        left + pw / 2 - i64::from(text_width(x_label, 1)) / 2,
        h - 24,
        x_label,
        BLACK,
        1,
    );
    c.text(8, top - 14, y_label, BLACK, 1);
    for (k, s) in series.iter().enumerate() {
        let col = PALETTE[k % PALETTE.len()];
        for pair in s.points.windows(2) {
            c.line(px(pair[0].0), py(pair[0].1), px(pair[1].0), py(pair[1].1), col, 2);
        }
        for (i, &(x, y)) in s.points.iter().enumerate() {
            c.fill_rect(px(x) - 3, py(y) - 3, 7, 7, col);
            if let Some(e) = s.errors.as_ref().and_then(|e| e.get(i)).filter(|e| **e > 0.0) {
                c.line(px(x), py(y - e), px(x), py(y + e), col, 1);
                c.line(px(x) - 4, py(y - e), px(x) + 4, py(y - e), col, 1);
                c.line(px(x) - 4, py(y + e), px(x) + 4, py(y + e), col, 1);
            }
        }
        let ly = top + 10 + k as i64 * 18;
        c.fill_rect(left + pw + 16, ly, 14, 7, col);
        c.text(left + pw + 36, ly, &s.label, BLACK, 1);
    }
    Ok(c)
}
