//! Loss-curve PNG of a run (issue 5 item 3): every `metrics.csv` loss column and the validation loss against the
//! step, on a log₁₀ y axis, drawn with the `image` crate and a built-in 3×5 pixel font (no system fonts).

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::error::{Result, TrainError};
use crate::run_folder::{METRIC_TAIL, read_table};

const W: u32 = 900;
const H: u32 = 540;
const LEFT: u32 = 70;
const RIGHT: u32 = 160;
const TOP: u32 = 20;
const BOTTOM: u32 = 40;
const PALETTE: [[u8; 3]; 6] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
    [140, 86, 75],
    [23, 190, 207],
];
const VALID_COLOUR: [u8; 3] = [214, 39, 40];

/// A named series of (step, value) points.
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points; non-positive or non-finite values are skipped on the log axis.
    pub points: Vec<(f64, f64)>,
    /// Line colour.
    pub colour: [u8; 3],
    /// Draw dots instead of a line.
    pub dots: bool,
}

/// Reads `metrics.csv` (and `valid.csv` when it has rows) and writes the plot to `out`.
pub fn plot_run(metrics: &Path, valid: &Path, out: &Path) -> Result<()> {
    let table = read_table(metrics)?;
    let n_loss_cols = table.header.len().saturating_sub(1 + METRIC_TAIL.len() - 1);
    let mut series = Vec::new();
    for col in 0..n_loss_cols {
        series.push(Series {
            name: table.header[col + 1].clone(),
            points: table.rows.iter().map(|(s, v)| (*s as f64, v[col])).collect(),
            colour: PALETTE[col % PALETTE.len()],
            dots: false,
        });
    }
    if valid.exists() {
        let v = read_table(valid)?;
        if !v.rows.is_empty() {
            series.push(Series {
                name: "valid".into(),
                points: v
                    .rows
                    .iter()
                    .map(|(s, vals)| (*s as f64, *vals.last().unwrap_or(&f64::NAN)))
                    .collect(),
                colour: VALID_COLOUR,
                dots: true,
            });
        }
    }
    let img = render(&series);
    let tmp = out.with_file_name(".tmp_plot.png");
    img.save(&tmp)
        .map_err(|e| TrainError::Other(format!("write plot {}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, out).map_err(crate::error::io_err("rename plot into place", out))
}

/// Draws the series on a log₁₀ y axis.
pub fn render(series: &[Series]) -> RgbImage {
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    let usable = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite() && y > 0.0;
    let pts = || series.iter().flat_map(|s| s.points.iter().copied().filter(usable));
    let (mut x0, mut x1) = pts().fold((f64::MAX, f64::MIN), |(a, b), (x, _)| (a.min(x), b.max(x)));
    let (mut y0, mut y1) = pts().fold((f64::MAX, f64::MIN), |(a, b), (_, y)| {
        (a.min(y.log10()), b.max(y.log10()))
    });
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.0, 1.0, -1.0, 0.0);
    }
    if x1 - x0 < 1e-9 {
        x1 = x0 + 1.0;
    }
    (y0, y1) = (y0.floor(), y1.ceil().max(y0.floor() + 1.0));
    let (pw, ph) = ((W - LEFT - RIGHT) as f64, (H - TOP - BOTTOM) as f64);
    let px = |x: f64| LEFT as f64 + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| TOP as f64 + (y1 - y.log10()) / (y1 - y0) * ph;
    let grey = Rgb([200, 200, 200]);
    let black = Rgb([0, 0, 0]);
    // Decade grid lines and labels "1e-3".
    for d in (y0 as i64)..=(y1 as i64) {
        let y = py(10f64.powi(d as i32));
        line(&mut img, LEFT as f64, y, (W - RIGHT) as f64, y, grey);
        text(&mut img, 4, y as i64 - 5, &format!("1e{d}"), black);
    }
    // Five x ticks.
    for i in 0..=4 {
        let x = x0 + (x1 - x0) * i as f64 / 4.0;
        let xp = px(x);
        line(&mut img, xp, (H - BOTTOM) as f64, xp, (H - BOTTOM + 4) as f64, black);
        let label = format!("{}", x.round() as i64);
        text(
            &mut img,
            xp as i64 - 4 * label.len() as i64,
            (H - BOTTOM + 10) as i64,
            &label,
            black,
        );
    }
    text(&mut img, (W - RIGHT) as i64 - 40, (H - 14) as i64, "step", black);
    line(
        &mut img,
        LEFT as f64,
        TOP as f64,
        LEFT as f64,
        (H - BOTTOM) as f64,
        black,
    );
    line(
        &mut img,
        LEFT as f64,
        (H - BOTTOM) as f64,
        (W - RIGHT) as f64,
        (H - BOTTOM) as f64,
        black,
    );
    for (k, s) in series.iter().enumerate() {
        let c = Rgb(s.colour);
        let mut prev: Option<(f64, f64)> = None;
        for p in s.points.iter().copied().filter(usable) {
            let q = (px(p.0), py(p.1));
            if s.dots {
                for dx in -2..=2 {
                    for dy in -2..=2 {
                        put(&mut img, q.0 as i64 + dx, q.1 as i64 + dy, c);
                    }
                }
            } else if let Some(a) = prev {
                line(&mut img, a.0, a.1, q.0, q.1, c);
            }
            prev = Some(q);
        }
        let ly = TOP as i64 + 14 * k as i64;
        for dx in 0..16 {
            for dy in 0..3 {
                put(&mut img, (W - RIGHT + 12) as i64 + dx, ly + 4 + dy, c);
            }
        }
        text(&mut img, (W - RIGHT + 32) as i64, ly, &s.name, black);
    }
    img
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn line(img: &mut RgbImage, xa: f64, ya: f64, xb: f64, yb: f64, c: Rgb<u8>) {
    let n = ((xb - xa).abs().max((yb - ya).abs()).ceil() as i64).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        put(
            img,
            (xa + t * (xb - xa)).round() as i64,
            (ya + t * (yb - ya)).round() as i64,
            c,
        );
    }
}

/// Draws `s` with the 3×5 font at scale 2 (6×10 pixels per glyph, 8-pixel advance).
fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, c: Rgb<u8>) {
    for (i, ch) in s.chars().enumerate() {
        let rows = glyph(ch.to_ascii_lowercase());
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) != 0 {
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        put(img, x + 8 * i as i64 + 2 * col + dx, y + 2 * r as i64 + dy, c);
                    }
                }
            }
        }
    }
}

/// 3×5 glyph rows (bit 2 = left column); unknown characters draw as a box.
fn glyph(ch: char) -> [u8; 5] {
    match ch {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 3, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        '_' => [0, 0, 0, 0, 7],
        ' ' => [0; 5],
        'a' => [2, 5, 7, 5, 5],
        'b' => [6, 5, 6, 5, 6],
        'c' => [3, 4, 4, 4, 3],
        'd' => [6, 5, 5, 5, 6],
        'e' => [7, 4, 6, 4, 7],
        'f' => [7, 4, 6, 4, 4],
        'g' => [3, 4, 5, 5, 3],
        'h' => [5, 5, 7, 5, 5],
        'i' => [7, 2, 2, 2, 7],
        'j' => [1, 1, 1, 5, 2],
        'k' => [5, 5, 6, 5, 5],
        'l' => [4, 4, 4, 4, 7],
        'm' => [5, 7, 7, 5, 5],
        'n' => [6, 5, 5, 5, 5],
        'o' => [2, 5, 5, 5, 2],
        'p' => [6, 5, 6, 4, 4],
        'q' => [2, 5, 5, 6, 3],
        'r' => [6, 5, 6, 5, 5],
        's' => [3, 4, 2, 1, 6],
        't' => [7, 2, 2, 2, 2],
        'u' => [5, 5, 5, 5, 7],
        'v' => [5, 5, 5, 5, 2],
        'w' => [5, 5, 7, 7, 5],
        'x' => [5, 5, 2, 5, 5],
        'y' => [5, 5, 2, 2, 2],
        'z' => [7, 1, 2, 4, 7],
        _ => [7, 5, 5, 5, 7],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_are_drawn_in_their_colours() {
        let s = Series {
            name: "rec".into(),
            points: (1..=50).map(|i| (i as f64, 1.0 / i as f64)).collect(),
            colour: PALETTE[0],
            dots: false,
        };
        let img = render(&[s]);
        let coloured = img.pixels().filter(|p| p.0 == PALETTE[0]).count();
        assert!(coloured > 200, "only {coloured} curve pixels");
        // First point (1, 1.0) is at the top-left corner of the plot area: y = 10^0 is the top decade.
        assert_eq!(img.get_pixel(LEFT, TOP).0, PALETTE[0]);
    }
}
