//! Inline SVG plots: a histogram, a timeline of marks in rows, lines over
//! time. Every text goes through [`esc`]; every plot is an `<svg>` with a
//! `data-plot` attribute naming it and a `data-points` attribute with the
//! number of data points drawn (what a test looks for).

use std::fmt::Write;

/// `s` with `&`, `<`, `>`, `"` and `'` as character references: safe in
/// element content and in quoted attribute values.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

const W: f64 = 720.0;
const H: f64 = 220.0;
/// Left, right, top and bottom margins.
const ML: f64 = 60.0;
const MR: f64 = 16.0;
const MT: f64 = 12.0;
const MB: f64 = 36.0;

/// A round step of about `span / 5`.
fn step(span: f64) -> f64 {
    if span <= 0.0 || !span.is_finite() {
        return 1.0;
    }
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let n = raw / mag;
    mag * if n < 1.5 {
        1.0
    } else if n < 3.5 {
        2.0
    } else if n < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A number for an axis label.
fn num(v: f64) -> String {
    if v.abs() >= 100.0 || v == v.trunc() {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

fn open(o: &mut String, name: &str, title: &str, points: usize) {
    let _ = write!(
        o,
        r#"<svg xmlns="http://www.w3.org/2000/svg" class="plot" data-plot="{}" data-points="{points}" viewBox="0 0 {W} {H}" width="{W}" height="{H}" role="img"><title>{}</title>"#,
        esc(name),
        esc(title)
    );
}

/// Axes with ticks for x in `x0..x1` and y in `y0..y1`.
fn axes(o: &mut String, (x0, x1): (f64, f64), (y0, y1): (f64, f64), xlabel: &str, ylabel: &str) {
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    let _ = write!(
        o,
        r##"<g class="axes"><line x1="{ML}" y1="{}" x2="{}" y2="{}" stroke="#444"/><line x1="{ML}" y1="{MT}" x2="{ML}" y2="{}" stroke="#444"/>"##,
        MT + ph,
        ML + pw,
        MT + ph,
        MT + ph
    );
    let sx = step(x1 - x0);
    let mut v = (x0 / sx).ceil() * sx;
    while v <= x1 + sx * 1e-9 {
        let x = ML + (v - x0) / (x1 - x0).max(f64::MIN_POSITIVE) * pw;
        let _ = write!(
            o,
            r##"<line x1="{x:.1}" y1="{}" x2="{x:.1}" y2="{}" stroke="#444"/><text x="{x:.1}" y="{}" text-anchor="middle">{}</text>"##,
            MT + ph,
            MT + ph + 4.0,
            MT + ph + 16.0,
            num(v)
        );
        v += sx;
    }
    if y1 > y0 {
        let sy = step(y1 - y0);
        let mut v = (y0 / sy).ceil() * sy;
        while v <= y1 + sy * 1e-9 {
            let y = MT + ph - (v - y0) / (y1 - y0) * ph;
            let _ = write!(
                o,
                r##"<line x1="{}" y1="{y:.1}" x2="{ML}" y2="{y:.1}" stroke="#444"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                ML - 4.0,
                ML - 6.0,
                y + 4.0,
                num(v)
            );
            v += sy;
        }
    }
    let _ = write!(
        o,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text><text x="14" y="{}" text-anchor="middle" transform="rotate(-90 14 {})">{}</text></g>"#,
        ML + pw / 2.0,
        H - 4.0,
        esc(xlabel),
        MT + ph / 2.0,
        MT + ph / 2.0,
        esc(ylabel)
    );
}

fn empty(o: &mut String, what: &str) {
    let _ = write!(
        o,
        r#"<text x="{}" y="{}" text-anchor="middle" class="none">{}</text>"#,
        W / 2.0,
        H / 2.0,
        esc(what)
    );
}

/// A histogram: bin `i` spans `from + i·width … from + (i+1)·width`.
pub fn histogram(
    name: &str,
    title: &str,
    xlabel: &str,
    from: f64,
    width: f64,
    counts: &[u64],
) -> String {
    let mut o = String::new();
    let bars = counts.iter().filter(|c| **c > 0).count();
    open(&mut o, name, title, bars);
    let top = counts.iter().copied().max().unwrap_or(0) as f64;
    if counts.is_empty() {
        empty(&mut o, "no samples");
        o.push_str("</svg>");
        return o;
    }
    let x1 = from + width * counts.len() as f64;
    axes(&mut o, (from, x1), (0.0, top), xlabel, "count");
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    let bw = pw / counts.len() as f64;
    for (i, &c) in counts.iter().enumerate() {
        if c == 0 {
            continue;
        }
        let h = c as f64 / top * ph;
        let lo = from + width * i as f64;
        let _ = write!(
            o,
            r#"<rect class="bar" x="{:.1}" y="{:.1}" width="{:.1}" height="{h:.1}"><title>{} … {} µs: {c}</title></rect>"#,
            ML + bw * i as f64 + 0.5,
            MT + ph - h,
            (bw - 1.0).max(0.5),
            num(lo),
            num(lo + width)
        );
    }
    o.push_str("</svg>");
    o
}

/// One mark of a [`timeline`]: time (s), row, tooltip.
pub struct Dot<'a> {
    /// Seconds from the start.
    pub t: f64,
    /// Row index into the rows given.
    pub row: usize,
    /// Text of its tooltip.
    pub text: &'a str,
}

/// Marks in named rows over `0 … span` seconds.
pub fn timeline(name: &str, title: &str, span: f64, rows: &[&str], dots: &[Dot<'_>]) -> String {
    let mut o = String::new();
    open(&mut o, name, title, dots.len());
    let span = span.max(1e-3);
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    axes(&mut o, (0.0, span), (0.0, 0.0), "time (s)", "");
    let rh = ph / rows.len().max(1) as f64;
    for (i, r) in rows.iter().enumerate() {
        let y = MT + rh * (i as f64 + 0.5);
        let _ = write!(
            o,
            r##"<line x1="{ML}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            ML + pw,
            ML - 6.0,
            y + 4.0,
            esc(r)
        );
    }
    for d in dots {
        let x = ML + d.t / span * pw;
        let y = MT + rh * (d.row as f64 + 0.5);
        let _ = write!(
            o,
            r#"<circle class="mark {}" cx="{x:.1}" cy="{y:.1}" r="4"><title>{:.6} s: {}</title></circle>"#,
            esc(rows.get(d.row).copied().unwrap_or("")),
            d.t,
            esc(d.text)
        );
    }
    o.push_str("</svg>");
    o
}

/// Lines over time: one per series (label, points of (s, value)).
pub fn lines(
    name: &str,
    title: &str,
    ylabel: &str,
    series: &[(String, &[(f64, f64)])],
    mark_y: Option<(f64, &str)>,
) -> String {
    let mut o = String::new();
    let n: usize = series.iter().map(|s| s.1.len()).sum();
    open(&mut o, name, title, n);
    if n == 0 {
        empty(&mut o, "no samples");
        o.push_str("</svg>");
        return o;
    }
    let pts = series.iter().flat_map(|s| s.1.iter());
    let (mut x0, mut x1, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0f64);
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y1 = y1.max(y);
    }
    if let Some((m, _)) = mark_y {
        y1 = y1.max(m);
    }
    let x1 = if x1 > x0 { x1 } else { x0 + 1e-3 };
    let y1 = if y1 > 0.0 { y1 * 1.05 } else { 1.0 };
    axes(&mut o, (x0, x1), (0.0, y1), "time (s)", ylabel);
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    let px = |x: f64| ML + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| MT + ph - y / y1 * ph;
    if let Some((m, label)) = mark_y {
        let _ = write!(
            o,
            r##"<line class="limit" x1="{ML}" y1="{:.1}" x2="{}" y2="{:.1}" stroke="#c00" stroke-dasharray="4 3"/><text x="{}" y="{:.1}" text-anchor="end" fill="#c00">{}</text>"##,
            py(m),
            ML + pw,
            py(m),
            ML + pw,
            py(m) - 3.0,
            esc(label)
        );
    }
    const COLOURS: [&str; 6] = [
        "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2",
    ];
    for (i, (label, points)) in series.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let mut d = String::new();
        for &(x, y) in points.iter() {
            let _ = write!(d, "{:.1},{:.1} ", px(x), py(y));
        }
        let _ = write!(
            o,
            r#"<polyline class="series" fill="none" stroke="{c}" stroke-width="1.2" points="{}"><title>{}</title></polyline><text x="{}" y="{}" fill="{c}">{}</text>"#,
            d.trim_end(),
            esc(label),
            ML + 8.0 + 110.0 * i as f64,
            MT + 12.0,
            esc(label)
        );
    }
    o.push_str("</svg>");
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup_and_quotes() {
        assert_eq!(
            esc(r#"<script>"a" & 'b'</script>"#),
            "&lt;script&gt;&quot;a&quot; &amp; &#39;b&#39;&lt;/script&gt;"
        );
    }

    #[test]
    fn histogram_draws_a_bar_per_filled_bin() {
        let s = histogram("h", "T", "µs", 100.0, 10.0, &[3, 0, 1]);
        assert!(s.starts_with("<svg") && s.ends_with("</svg>"));
        assert!(s.contains(r#"data-points="2""#), "{s}");
        assert_eq!(s.matches("<rect class=\"bar\"").count(), 2);
        assert!(s.contains("100 … 110 µs: 3"), "{s}");
        let none = histogram("h", "T", "µs", 0.0, 1.0, &[]);
        assert!(none.contains("no samples") && none.contains(r#"data-points="0""#));
    }

    #[test]
    fn timeline_places_and_escapes_marks() {
        let dots = [
            Dot {
                t: 0.0,
                row: 0,
                text: "slave 8 <restart>",
            },
            Dot {
                t: 2.0,
                row: 1,
                text: "x",
            },
        ];
        let s = timeline("t", "T", 2.0, &["restart", "diag"], &dots);
        assert_eq!(s.matches("<circle").count(), 2);
        assert!(s.contains("slave 8 &lt;restart&gt;"));
        assert!(!s.contains("<restart>"));
        // The last mark sits at the right end of the plot.
        assert!(s.contains(&format!(r#"cx="{:.1}""#, W - MR)), "{s}");
    }

    #[test]
    fn lines_draw_one_polyline_per_series_and_the_limit() {
        let a = [(0.0, 100.0), (1.0, 200.0)];
        let s = lines(
            "r",
            "T",
            "µs",
            &[("master 2".into(), &a[..])],
            Some((300.0, "TTR")),
        );
        assert_eq!(s.matches("<polyline").count(), 1);
        assert!(s.contains("class=\"limit\"") && s.contains(">TTR<"));
        assert!(s.contains(r#"data-points="2""#));
    }

    #[test]
    fn steps_are_round() {
        assert_eq!(step(10.0), 2.0);
        assert_eq!(step(1000.0), 200.0);
        assert_eq!(step(0.3), 0.05);
    }
}
