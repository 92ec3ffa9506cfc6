"""Reports of a scan: PNG error maps and the metrics table (`maps`), the HTML report (`html`)."""
