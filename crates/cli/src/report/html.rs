//! The report as one HTML page: inline CSS, inline SVG, no scripts, no
//! fonts or anything else fetched; every string from the capture, the
//! bus file or a GSD file is escaped ([`esc`]).

use super::model::{MarkKind, Report, Stat, Station};
use super::svg::{self, esc, Dot};
use std::fmt::Write;

const STYLE: &str = "\
body{font-family:sans-serif;margin:1.5em;color:#222;max-width:1100px}\
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;font-size:.9em}\
td,th{border:1px solid #ccc;padding:.2em .5em;text-align:right}\
th{background:#f0f0f0}td.l,th.l{text-align:left}\
.bar-bg{display:inline-block;width:80px;height:.8em;background:#eee;vertical-align:middle}\
.bar-fg{display:block;height:100%}\
.ok{background:#2a2}.warn{background:#e90}.bad{background:#d22}\
svg.plot{display:block;margin:.5em 0;font-size:11px;background:#fff;border:1px solid #ddd}\
svg .bar{fill:#1f77b4}svg .mark{fill-opacity:.7}\
svg .mark.restart{fill:#d22}svg .mark.diag{fill:#e90}svg .mark.error{fill:#800}svg .mark.state{fill:#1f77b4}\
svg .none{fill:#888}\
pre{background:#f7f7f7;padding:.5em;white-space:pre-wrap}\
.note{color:#666;font-size:.9em}";

/// The report as a page.
pub fn render(r: &Report) -> String {
    let mut o = String::with_capacity(64 * 1024);
    let _ = write!(
        o,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width\">\
         <meta name=\"generator\" content=\"dpctl report {}\">\
         <title>PROFIBUS report: {}</title><style>{STYLE}</style></head><body>\n",
        esc(env!("CARGO_PKG_VERSION")),
        esc(&r.capture)
    );
    let _ = writeln!(o, "<h1>PROFIBUS report: {}</h1>", esc(&r.capture));
    segment(&mut o, r);
    live_list(&mut o, r);
    station_table(&mut o, r);
    plots(&mut o, r);
    diagnoses(&mut o, r);
    events(&mut o, r);
    o.push_str(
        "<p class=\"note\">Made by <code>dpctl report</code> from the telegrams alone: \
         what software on an RS-485 adapter can see. Signal levels, reflections and \
         cabling need a physical-layer tester.</p>\n</body></html>\n",
    );
    o
}

fn opt_us(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.0} µs"))
}

fn segment(o: &mut String, r: &Report) {
    let s = &r.segment;
    let rate = match s.baud {
        Some(b) if b >= 1_000_000 => format!("{} Mbit/s ({})", b as f64 / 1e6, s.baud_source),
        Some(b) => format!("{} kbit/s ({})", b as f64 / 1e3, s.baud_source),
        None => "unknown (give --baud or --config)".into(),
    };
    let masters = if s.masters.is_empty() {
        "none seen".to_string()
    } else {
        s.masters
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let ttr = match (s.ttr_bits, s.ttr_us) {
        (Some(b), Some(u)) => format!("{b} bit times ({u:.0} µs)"),
        (Some(b), None) => format!("{b} bit times"),
        _ => "unknown (give --config)".into(),
    };
    let rows: [(&str, String); 11] = [
        ("Rate", rate),
        ("Masters", masters),
        ("TTR", ttr),
        ("Start", s.start.clone()),
        ("Span", format!("{:.3} s", s.span_s)),
        ("Records", s.records.to_string()),
        ("Telegrams", s.telegrams.to_string()),
        ("Tokens", s.tokens.to_string()),
        ("Illegal telegrams", s.illegal.to_string()),
        (
            "No answer / retries",
            format!("{} / {}", s.no_answer, s.retries),
        ),
        ("Restarts", s.restarts.to_string()),
    ];
    o.push_str("<h2 id=\"segment\">Segment</h2>\n<table class=\"segment\">");
    for (k, v) in rows {
        let _ = write!(
            o,
            "<tr><th class=\"l\">{}</th><td class=\"l\">{}</td></tr>",
            esc(k),
            esc(&v)
        );
    }
    o.push_str("</table>\n");
}

fn health_bar(h: u8) -> String {
    let class = match h {
        90..=100 => "ok",
        60..=89 => "warn",
        _ => "bad",
    };
    format!(
        "<span class=\"bar-bg\" title=\"{h} %\"><span class=\"bar-fg {class}\" style=\"width:{h}%\"></span></span> {h}"
    )
}

fn live_list(o: &mut String, r: &Report) {
    o.push_str(
        "<h2 id=\"live-list\">Live list</h2>\n<table class=\"live-list\"><tr><th>Address</th>\
         <th class=\"l\">Name</th><th class=\"l\">Role</th><th class=\"l\">DP state</th>\
         <th>Master</th><th class=\"l\">Ident</th><th class=\"l\">Health</th></tr>",
    );
    for s in &r.stations {
        let _ = write!(
            o,
            "<tr data-address=\"{}\"><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td>\
             <td class=\"l\">{}</td><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
            s.address,
            s.address,
            esc(&s.name),
            esc(s.role),
            esc(s.state.unwrap_or("–")),
            s.master.map_or("–".into(), |m| m.to_string()),
            esc(s.ident.as_deref().unwrap_or("–")),
            health_bar(s.health)
        );
    }
    o.push_str("</table>\n");
}

fn stat_cells(s: Option<Stat>) -> String {
    match s {
        Some(s) => format!(
            "<td>{:.0}</td><td>{:.0}</td><td>{:.0}</td>",
            s.min, s.mean, s.max
        ),
        None => "<td>–</td><td>–</td><td>–</td>".into(),
    }
}

fn station_row(o: &mut String, s: &Station) {
    let _ = write!(
        o,
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
         <td>{}</td><td>{}</td>{}{}</tr>",
        s.address,
        s.requests,
        s.answers,
        s.retries,
        s.no_answer,
        s.illegal,
        s.diag_requests,
        s.ext_diag,
        s.restarts,
        stat_cells(s.response_us),
        stat_cells(s.cycle_us),
    );
}

fn station_table(o: &mut String, r: &Report) {
    o.push_str(
        "<h2 id=\"stations\">Stations</h2>\n<table class=\"stations\"><tr><th rowspan=\"2\">Address</th>\
         <th rowspan=\"2\">Requests</th><th rowspan=\"2\">Answers</th><th rowspan=\"2\">Retries</th>\
         <th rowspan=\"2\">No answer</th><th rowspan=\"2\">Illegal</th><th rowspan=\"2\">Diag requests</th>\
         <th rowspan=\"2\">Ext_Diag</th><th rowspan=\"2\">Restarts</th>\
         <th colspan=\"3\">Response time (µs)</th><th colspan=\"3\">Cycle time (µs)</th></tr>\
         <tr><th>min</th><th>mean</th><th>max</th><th>min</th><th>mean</th><th>max</th></tr>",
    );
    for s in r.stations.iter().filter(|s| s.role == "slave") {
        station_row(o, s);
    }
    o.push_str("</table>\n");
    let masters: Vec<_> = r.stations.iter().filter(|s| s.role == "master").collect();
    if !masters.is_empty() {
        o.push_str(
            "<h3>Masters</h3><table class=\"masters\"><tr><th>Address</th><th>Tokens</th>\
             <th>Rotation min</th><th>mean</th><th>max</th><th>TTR</th></tr>",
        );
        for m in masters {
            let rot = m.rotation_us;
            let _ = write!(
                o,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                m.address,
                m.tokens.unwrap_or(0),
                opt_us(rot.map(|s| s.min)),
                opt_us(rot.map(|s| s.mean)),
                opt_us(rot.map(|s| s.max)),
                opt_us(r.segment.ttr_us),
            );
        }
        o.push_str("</table>\n");
    }
}

fn plots(o: &mut String, r: &Report) {
    o.push_str("<h2 id=\"plots\">Plots</h2>\n<h3>Data_Exchange cycle time</h3>\n");
    let h = &r.cycle_histogram;
    o.push_str(&svg::histogram(
        "cycle-time",
        "Data_Exchange cycle time per slave (µs)",
        "cycle time (µs)",
        h.from_us,
        h.bin_us,
        &h.counts,
    ));
    o.push_str("\n<h3>Response time</h3>\n");
    let h = &r.response_histogram;
    o.push_str(&svg::histogram(
        "response-time",
        "Response time, request end to answer start (µs)",
        "response time (µs)",
        h.from_us,
        h.bin_us,
        &h.counts,
    ));
    o.push_str("\n<h3>Timeline</h3>\n");
    let rows: Vec<&str> = MarkKind::ALL.iter().map(|k| k.name()).collect();
    let dots: Vec<Dot<'_>> = r
        .timeline
        .iter()
        .map(|m| Dot {
            t: m.t_s,
            row: MarkKind::ALL.iter().position(|k| *k == m.kind).unwrap_or(0),
            text: &m.text,
        })
        .collect();
    o.push_str(&svg::timeline(
        "timeline",
        "Restarts, diagnoses, errors and state changes over time",
        r.segment.span_s,
        &rows,
        &dots,
    ));
    if r.timeline_dropped > 0 {
        let _ = write!(
            o,
            "<p class=\"note\">{} further marks left out.</p>",
            r.timeline_dropped
        );
    }
    o.push_str("\n<h3>Token rotation</h3>\n");
    let series: Vec<(String, &[(f64, f64)])> = r
        .rotation
        .iter()
        .map(|s| (format!("master {}", s.master), &s.points[..]))
        .collect();
    o.push_str(&svg::lines(
        "token-rotation",
        "Token rotation time per master over time (µs)",
        "rotation (µs)",
        &series,
        r.segment.ttr_us.map(|t| (t, "TTR")),
    ));
    o.push('\n');
}

fn diagnoses(o: &mut String, r: &Report) {
    o.push_str("<h2 id=\"diagnoses\">Diagnoses</h2>\n");
    if r.diagnoses.is_empty() {
        o.push_str("<p>No Slave_Diag answers in the capture.</p>\n");
        return;
    }
    for d in &r.diagnoses {
        let _ = write!(
            o,
            "<h3>Slave {} at {:.6} s{}</h3><p class=\"note\">Slave_Diag {}{}</p><ul>",
            d.address,
            d.t_s,
            if d.count > 1 {
                format!(" ({} times)", d.count)
            } else {
                String::new()
            },
            esc(&d.raw),
            d.gsd
                .as_ref()
                .map_or(String::new(), |g| format!("; texts from {}", esc(g)))
        );
        for l in &d.lines {
            let _ = write!(o, "<li>{}</li>", esc(l));
        }
        o.push_str("</ul>\n");
    }
}

/// Events listed at most in the table (the plot has them all).
const LISTED: usize = 300;

fn events(o: &mut String, r: &Report) {
    o.push_str("<h2 id=\"events\">Events</h2>\n<table class=\"events\"><tr><th>Time (s)</th><th class=\"l\">Kind</th><th class=\"l\">What</th></tr>");
    for m in r
        .timeline
        .iter()
        .filter(|m| m.kind != MarkKind::State)
        .take(LISTED)
    {
        let _ = write!(
            o,
            "<tr class=\"{}\"><td>{:.6}</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
            m.kind.name(),
            m.t_s,
            m.kind.name(),
            esc(&m.text)
        );
    }
    o.push_str("</table>\n");
}

#[cfg(test)]
mod tests {
    use super::super::model::{Diagnosis, Histogram, Mark, Segment};
    use super::*;

    fn sample() -> Report {
        Report {
            capture: "<x>.pcapng".into(),
            segment: Segment {
                baud: Some(1_500_000),
                baud_source: "guessed",
                masters: vec![2],
                span_s: 2.0,
                ..Segment::default()
            },
            stations: vec![Station {
                address: 8,
                name: "valve <&>".into(),
                role: "slave",
                state: Some("data_exchange"),
                health: 75,
                requests: 10,
                answers: 9,
                response_us: Some(Stat {
                    min: 10.0,
                    mean: 20.0,
                    max: 30.0,
                    count: 9,
                }),
                ..Station::default()
            }],
            diagnoses: vec![Diagnosis {
                address: 8,
                t_s: 1.0,
                count: 2,
                raw: "08 0C".into(),
                lines: vec!["device: \"overtemp\" <b>".into()],
                gsd: Some("X.GSD".into()),
            }],
            timeline: vec![Mark {
                t_s: 1.5,
                kind: MarkKind::Restart,
                address: Some(8),
                text: "slave 8: data_exchange → diag".into(),
            }],
            cycle_histogram: Histogram {
                from_us: 1000.0,
                bin_us: 10.0,
                counts: vec![4, 1],
                samples: 5,
            },
            ..Report::default()
        }
    }

    #[test]
    fn page_is_self_contained_and_escaped() {
        let p = render(&sample());
        assert!(p.starts_with("<!DOCTYPE html>"));
        for bad in ["<script", "http://", "https://", "@import", "url(", "<link"] {
            // The SVG namespace is an identifier, never fetched.
            let p = p.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
            assert!(!p.contains(bad), "{bad} in the page");
        }
        assert!(p.contains("valve &lt;&amp;&gt;"));
        assert!(p.contains("&lt;x&gt;.pcapng"));
        assert!(p.contains("device: &quot;overtemp&quot; &lt;b&gt;"));
        assert!(!p.contains("<b>"));
    }

    #[test]
    fn page_has_the_sections_and_plots() {
        let p = render(&sample());
        for id in [
            "segment",
            "live-list",
            "stations",
            "plots",
            "diagnoses",
            "events",
        ] {
            assert!(p.contains(&format!("id=\"{id}\"")), "{id}");
        }
        for plot in ["cycle-time", "response-time", "timeline", "token-rotation"] {
            assert!(p.contains(&format!("data-plot=\"{plot}\"")), "{plot}");
        }
        assert!(p.contains("data-plot=\"cycle-time\" data-points=\"2\""));
        assert!(p.contains("data-plot=\"timeline\" data-points=\"1\""));
        assert!(p.contains("class=\"mark restart\""));
        assert!(p.contains("1.5 Mbit/s (guessed)"));
        assert!(p.contains("(2 times)") && p.contains("texts from X.GSD"));
        assert!(p.contains("<td>10</td><td>20</td><td>30</td>"));
        assert!(p.contains("bar-fg warn"));
    }
}
