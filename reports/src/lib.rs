//! Report folders: one per command that produces results (`evaluate`, `sil`, `diagnose`,
//! `validate-diagnosis`). A report is Markdown and a self-contained HTML page with the same
//! tables and SVG plots, plus machine-readable JSON with every number; the folder is written
//! completely or not at all.
//!
//! [`plot`] draws the SVG plots the reports and the model cards embed.

pub mod plot;

use std::fmt::Write as _;
use std::path::Path;

use crate::plot::escape;

/// The file that marks a folder as a report (an existing report folder may be replaced).
pub const REPORT_MARKER: &str = "report.md";

/// A report: a title, an introduction and sections.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    /// Title.
    pub title: String,
    /// Paragraphs under the title.
    pub intro: Vec<String>,
    /// Sections in order.
    pub sections: Vec<Section>,
}

/// A section: heading, paragraphs, tables and figures, in that order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Section {
    /// Heading.
    pub heading: String,
    /// Paragraphs (Markdown inline code with backticks is kept in both outputs).
    pub paragraphs: Vec<String>,
    /// Tables.
    pub tables: Vec<Table>,
    /// Figures.
    pub figures: Vec<Figure>,
}

/// A table with a caption.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// Caption above the table.
    pub caption: String,
    /// Column headers.
    pub header: Vec<String>,
    /// Rows of cells.
    pub rows: Vec<Vec<String>>,
}

/// An SVG figure written as its own file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Figure {
    /// File name inside the report folder (`fig07_plant.svg`).
    pub file: String,
    /// Caption.
    pub caption: String,
    /// The SVG document.
    pub svg: String,
}

impl Report {
    /// The report as Markdown.
    #[must_use]
    pub fn markdown(&self) -> String {
        let mut md = format!("# {}\n\n", self.title);
        for paragraph in &self.intro {
            let _ = writeln!(md, "{paragraph}\n");
        }
        for section in &self.sections {
            let _ = writeln!(md, "## {}\n", section.heading);
            for paragraph in &section.paragraphs {
                let _ = writeln!(md, "{paragraph}\n");
            }
            for table in &section.tables {
                let _ = writeln!(md, "{}\n", table.caption);
                let _ = writeln!(md, "| {} |", table.header.join(" | "));
                let _ = writeln!(md, "|{}", " --- |".repeat(table.header.len()));
                for row in &table.rows {
                    let _ = writeln!(md, "| {} |", row.join(" | "));
                }
                let _ = writeln!(md);
            }
            for figure in &section.figures {
                let _ = writeln!(md, "![{}]({})\n\n*{}*\n", escape(&figure.caption), figure.file, figure.caption);
            }
        }
        md
    }

    /// The report as one HTML page (inline style; figures referenced as files beside it).
    #[must_use]
    pub fn html(&self) -> String {
        let mut html = format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            escape(&self.title),
            escape(&self.title)
        );
        for paragraph in &self.intro {
            let _ = writeln!(html, "<p>{}</p>", inline(paragraph));
        }
        for section in &self.sections {
            let _ = writeln!(html, "<section>\n<h2>{}</h2>", escape(&section.heading));
            for paragraph in &section.paragraphs {
                let _ = writeln!(html, "<p>{}</p>", inline(paragraph));
            }
            for table in &section.tables {
                html_table(&mut html, table);
            }
            for figure in &section.figures {
                let _ = writeln!(
                    html,
                    "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
                    escape(&figure.file),
                    escape(&figure.caption),
                    inline(&figure.caption)
                );
            }
            let _ = writeln!(html, "</section>");
        }
        html.push_str("</body>\n</html>\n");
        html
    }
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}\
h1{border-bottom:2px solid #444;padding-bottom:.2em}h2{margin-top:2em;border-bottom:1px solid #bbb}\
table{border-collapse:collapse;margin:.5em 0 1.5em}th,td{border:1px solid #bbb;padding:.25em .6em;text-align:right}\
th{background:#eee}td:first-child,th:first-child{text-align:left}caption{caption-side:top;text-align:left;font-weight:600;padding:.3em 0}\
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{font-style:italic;color:#555}\
code{background:#f3f3f3;padding:0 .2em}";

fn html_table(html: &mut String, table: &Table) {
    let _ = writeln!(html, "<table>\n<caption>{}</caption>\n<tr>", inline(&table.caption));
    for cell in &table.header {
        let _ = write!(html, "<th>{}</th>", inline(cell));
    }
    let _ = writeln!(html, "</tr>");
    for row in &table.rows {
        let _ = write!(html, "<tr>");
        for cell in row {
            let _ = write!(html, "<td>{}</td>", inline(cell));
        }
        let _ = writeln!(html, "</tr>");
    }
    let _ = writeln!(html, "</table>");
}

/// Escapes text and turns Markdown `code` spans into `<code>`.
fn inline(text: &str) -> String {
    let escaped = escape(text);
    let mut out = String::new();
    for (idx, part) in escaped.split('`').enumerate() {
        if idx % 2 == 1 {
            let _ = write!(out, "<code>{part}</code>");
        } else {
            out.push_str(part);
        }
    }
    out
}

/// Writes the report folder `dir`: `report.md`, `report.html`, every figure, and `json_name`
/// with `json` (pretty-printed). Complete or absent.
pub fn write_report(
    dir: &Path,
    report: &Report,
    json_name: &str,
    json: &serde_json::Value,
) -> Result<(), std::io::Error> {
    let markdown = report.markdown();
    let html = report.html();
    let json = serde_json::to_string_pretty(json).map_err(std::io::Error::other)?;
    let result = firmware_sim::atomic::write_folder::<ReportWriteError>(dir, REPORT_MARKER, |tmp| {
        std::fs::write(tmp.join(REPORT_MARKER), &markdown)?;
        std::fs::write(tmp.join("report.html"), &html)?;
        std::fs::write(tmp.join(json_name), &json)?;
        for section in &report.sections {
            for figure in &section.figures {
                std::fs::write(tmp.join(&figure.file), &figure.svg)?;
            }
        }
        Ok(())
    });
    result.map_err(|error| std::io::Error::other(error.to_string()))
}

/// Errors while filling a report folder.
#[derive(Debug, thiserror::Error)]
enum ReportWriteError {
    #[error(transparent)]
    Folder(#[from] firmware_sim::atomic::FolderError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Report {
        Report {
            title: "Evaluation <test>".into(),
            intro: vec!["Uses `host-tools`.".into()],
            sections: vec![Section {
                heading: "Table 1".into(),
                paragraphs: vec![],
                tables: vec![Table {
                    caption: "ratios".into(),
                    header: vec!["alpha".into(), "ratio".into()],
                    rows: vec![vec!["0".into(), "11 %".into()]],
                }],
                figures: vec![Figure { file: "a.svg".into(), caption: "plot".into(), svg: "<svg/>".into() }],
            }],
        }
    }

    #[test]
    fn markdown_and_html_hold_the_same_content_escaped() {
        let report = sample();
        let md = report.markdown();
        assert!(md.contains("| 0 | 11 % |") && md.contains("![plot](a.svg)"));
        let html = report.html();
        assert!(html.contains("Evaluation &lt;test&gt;") && html.contains("<code>host-tools</code>"));
        assert!(html.contains("<td>11 %</td>") && html.contains("<img src=\"a.svg\""));
    }

    #[test]
    fn report_folder_is_written_whole() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("report");
        write_report(&dir, &sample(), "evaluation.json", &serde_json::json!({"x": 1})).unwrap();
        for file in ["report.md", "report.html", "evaluation.json", "a.svg"] {
            assert!(dir.join(file).is_file(), "{file}");
        }
    }
}
