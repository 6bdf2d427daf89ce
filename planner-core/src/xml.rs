//! XML text: escaping character data for the formats that embed XML
//! (KML, GDAL's GeoTIFF metadata, the costmap's SVG preview).

/// `text` escaped for XML character data, without the control characters
/// XML 1.0 forbids (and NUL, which would end the TIFF ASCII value).
pub(crate) fn xml_escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&apos;"),
            '\t' | '\n' | '\r' => s.push(c),
            c if c.is_control() => {}
            c => s.push(c),
        }
    }
    s
}
