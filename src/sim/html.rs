//! A self-contained HTML report of a run (issue 13): the verdict, tables and the SVG figures
//! inline, no script, no external file — it opens in any browser from the output folder or as
//! an attachment. `ddct bench` writes one per run (`report.html`).

use super::verdict::Check;

/// A table: caption, column heads, rows of cells (already formatted).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table {
    pub caption: String,
    pub head: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

/// Escapes text for HTML.
pub(crate) fn escape(s: &str) -> String {
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

fn table_html(t: &Table) -> String {
    let mut s = format!("<table>\n<caption>{}</caption>\n<tr>", escape(&t.caption));
    for h in &t.head {
        s.push_str(&format!("<th>{}</th>", escape(h)));
    }
    s.push_str("</tr>\n");
    for r in &t.rows {
        s.push_str("<tr>");
        for c in r {
            let class = match c.as_str() {
                "PASS" => " class=\"pass\"",
                "FAIL" => " class=\"fail\"",
                _ => "",
            };
            s.push_str(&format!("<td{class}>{}</td>", escape(c)));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table>\n");
    s
}

/// The verdict as a table (check, result, limit, measured).
pub(crate) fn verdict_table(checks: &[Check]) -> Table {
    Table {
        caption: "Verdict (the scenario's [limits])".into(),
        head: ["check", "result", "limit", "measured"]
            .map(String::from)
            .to_vec(),
        rows: checks
            .iter()
            .map(|c| {
                vec![
                    c.name.to_string(),
                    if c.pass { "PASS" } else { "FAIL" }.to_string(),
                    c.limit.clone(),
                    c.measured.clone(),
                ]
            })
            .collect(),
    }
}

/// The report: a heading with the overall result, the description, the tables, the figures.
/// An SVG document's XML declaration is dropped so that it embeds as inline SVG.
pub fn report(
    title: &str,
    description: &str,
    passed: bool,
    tables: &[Table],
    figures: &[(String, String)],
) -> String {
    let mut s =
        String::from("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    s.push_str(&format!("<title>{}</title>\n", escape(title)));
    s.push_str(
        "<style>\nbody{font-family:sans-serif;margin:2em;max-width:1200px}\n\
         table{border-collapse:collapse;margin:1em 0}\ncaption{text-align:left;font-weight:bold;padding:.3em 0}\n\
         th,td{border:1px solid #bbb;padding:.2em .6em;text-align:left}\nth{background:#eee}\n\
         td.pass{color:#1a7f37;font-weight:bold}\ntd.fail{color:#c62828;font-weight:bold}\n\
         .result{font-size:1.4em;font-weight:bold}\n.pass{color:#1a7f37}\n.fail{color:#c62828}\n\
         figure{margin:1em 0}\nfigure svg{max-width:100%;height:auto}\n</style>\n</head>\n<body>\n",
    );
    s.push_str(&format!("<h1>{}</h1>\n", escape(title)));
    let (class, word) = if passed {
        ("pass", "PASS")
    } else {
        ("fail", "FAIL")
    };
    s.push_str(&format!(
        "<p class=\"result {class}\">{word}</p>\n<p>{}</p>\n",
        escape(description)
    ));
    for t in tables {
        s.push_str(&table_html(t));
    }
    for (caption, svg) in figures {
        let body = match svg.find("<svg") {
            Some(i) => &svg[i..],
            None => svg.as_str(),
        };
        s.push_str(&format!(
            "<figure>\n<figcaption>{}</figcaption>\n{body}\n</figure>\n",
            escape(caption)
        ));
    }
    s.push_str("</body>\n</html>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_and_embeds() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
        let checks = [Check {
            name: "lockup_s_max",
            limit: "≤ 2 s".into(),
            measured: "2.5 s".into(),
            pass: false,
        }];
        let html = report(
            "t <1>",
            "d",
            false,
            &[verdict_table(&checks)],
            &[(
                "fig".into(),
                "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>".into(),
            )],
        );
        assert!(html.contains("<title>t &lt;1&gt;</title>"));
        assert!(html.contains("<td class=\"fail\">FAIL</td>") && html.contains("<td>≤ 2 s</td>"));
        assert!(!html.contains("<?xml") && html.contains("<svg xmlns"));
    }
}
