"""The self-contained HTML page: plotly.js inlined once (gzipped unless asked otherwise) and
the loader that draws each figure from its JSON, numeric arrays sent as typed arrays, one
trace shared by every figure, and pictures embedded as data URIs (large ones downscaled).
"""

from __future__ import annotations

import base64
import gzip
import html
import io
from pathlib import Path

import numpy as np

# Pictures larger than this are embedded downscaled to about twice a grid column's width
# (700 px on the 1400 px page, twice for sharp screens; 1280 keeps the door's three-planner
# page under 5 MB), as the smaller of a 256-colour PNG and a JPEG; the files keep every pixel.
PICTURE_MAX_BYTES = 300_000
PICTURE_MAX_WIDTH_PX = 1280


def _picture_data_uri(path: Path, full: bool) -> str:
    """The picture as a data URI; a large one (unless `full`) downscaled and re-encoded."""
    data = path.read_bytes()
    if full or len(data) <= PICTURE_MAX_BYTES:
        return "data:image/png;base64," + base64.b64encode(data).decode()
    from PIL import Image  # deferred: matplotlib's dependency, for a large picture only

    with Image.open(path) as image:
        rgba = image.convert("RGBA")
    flat = Image.new("RGB", rgba.size, "white")
    flat.paste(rgba, mask=rgba.getchannel("A"))  # transparency onto the page's white
    if flat.width > PICTURE_MAX_WIDTH_PX:
        height = round(flat.height * PICTURE_MAX_WIDTH_PX / flat.width)
        flat = flat.resize((PICTURE_MAX_WIDTH_PX, height), Image.Resampling.LANCZOS)
    encoded = []
    for mime, save in (
        ("image/png", lambda out: flat.quantize(256).save(out, "PNG", optimize=True)),
        ("image/jpeg", lambda out: flat.save(out, "JPEG", quality=85)),
    ):
        buffer = io.BytesIO()
        save(buffer)
        encoded.append((len(buffer.getvalue()), mime, buffer.getvalue()))
    _, mime, best = min(encoded)
    return f"data:{mime};base64," + base64.b64encode(best).decode()


def picture_html(path: Path, full: bool = False) -> str:
    """The picture at `path` with its name as caption (`full`: never downscaled)."""
    name = html.escape(path.name)
    return (
        f"<figure><img src='{_picture_data_uri(path, full)}' alt='{name}'>"
        f"<figcaption>{name}</figcaption></figure>"
    )


_STYLE = """
body{font-family:system-ui,sans-serif;margin:24px auto;max-width:1400px;color:#222}
table{border-collapse:collapse;margin:12px 0}th,td{border:1px solid #ccc;padding:4px 10px}
td{text-align:right;font-variant-numeric:tabular-nums}tr:nth-child(even){background:#f6f6f6}
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(600px,1fr));gap:12px}
.grid>*{min-width:0}
img{max-width:100%;border:1px solid #ddd}.note{color:#555;font-size:0.9em}
.headline{font-size:1.3em;margin:8px 0 16px}
"""


def lighter_trace(trace) -> dict:
    """A trace as plotly JSON, its numeric arrays as typed arrays (`_typed`)."""
    return _typed(trace.to_plotly_json())


def _typed(value):
    """Numeric arrays, anywhere in `value`, as plotly.js typed-array specs (base64, not a
    decimal list): floats as float32 (well under a micrometre at a part's scale), integers in
    the smallest type that holds them."""
    if isinstance(value, dict):
        return {k: _typed(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_typed(v) for v in value]
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "iuf" or value.ndim != 1:
        return value
    if value.dtype.kind == "f":
        value = value.astype(np.float32)
    else:
        lo, hi = (int(value.min()), int(value.max())) if value.size else (0, 0)
        kinds = (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32)
        value = value.astype(
            next(t for t in kinds if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max)
        )
    code = {"f": "f", "u": "u", "i": "i"}[value.dtype.kind] + str(value.dtype.itemsize)
    return {"dtype": code, "bdata": base64.b64encode(value.tobytes()).decode()}


def figure_html(figure, div_id: str, shared_first: bool = False) -> str:
    """A figure's place on the page and its data, drawn once plotly.js is loaded (`page_html`);
    with `shared_first`, its first trace is the page's shared trace 0."""
    data = [lighter_trace(t) for t in figure.data]
    if shared_first:
        data[0] = {"shared": 0}
    layout = figure.layout.to_plotly_json()
    height = int(layout.get("height") or 500)
    return (
        f"<div id='{div_id}' class='plot' style='width:100%;height:{height}px'></div>"
        f"<script type='application/json' data-figure='{div_id}'>"
        f"{_script_json({'data': data, 'layout': layout})}</script>"
    )


def _script_json(value) -> str:
    """JSON that can sit inside a <script> element ("</" would end it)."""
    from plotly.io.json import to_json_plotly  # deferred: plotly loads only for a page

    return to_json_plotly(value).replace("</", "<\\/")


# Unpacks plotly.js where it came gzipped (DecompressionStream: Chrome 80, Firefox 113,
# Safari 16.4), then draws every figure, its shared traces put back in.
_LOADER = """
(async () => {
  const packed = document.getElementById('scanplan-plotly-gz');
  if (!window.Plotly && packed) {
    try {
      const bytes = Uint8Array.from(atob(packed.textContent.trim()), c => c.charCodeAt(0));
      const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
      const script = document.createElement('script');
      script.textContent = await new Response(stream).text();
      document.head.appendChild(script);
    } catch (error) {
      document.body.insertAdjacentHTML('afterbegin', "<p class='note'>This browser cannot " +
        "unpack the 3-D views (" + error + "); write the report with --full-3d.</p>");
      return;
    }
  }
  const sharedText = document.getElementById('scanplan-shared').textContent;
  for (const element of document.querySelectorAll('script[data-figure]')) {
    const figure = JSON.parse(element.textContent);
    const shared = JSON.parse(sharedText);  // each figure its own copy: plotly writes to it
    const data = figure.data.map(t => ('shared' in t ? shared[t.shared] : t));
    Plotly.newPlot(element.dataset.figure, data, figure.layout, {responsive: true});
  }
})();
"""


def page_html(
    title: str, sections: list[str], shared: list[dict] | None = None, compress: bool = True
) -> str:
    """One self-contained page: the sections, plotly.js inlined once (gzipped if `compress`)
    and the loader that draws the figures (`figure_html`) with the `shared` traces."""
    import plotly  # deferred: plotly loads only when a page is written

    plotly_js = plotly.offline.get_plotlyjs()
    if compress:
        packed = base64.b64encode(gzip.compress(plotly_js.encode(), 9, mtime=0)).decode()
        library = (
            f"<script type='application/octet-stream' id='scanplan-plotly-gz'>{packed}</script>"
        )
        head_script = ""
    else:
        library, head_script = "", f"<script>{plotly_js}</script>"
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style>{head_script}</head><body>"
        + "\n".join(sections)
        + library
        + "<script type='application/json' id='scanplan-shared'>"
        + f"{_script_json(shared or [])}</script>"
        + f"<script>{_LOADER}</script></body></html>"
    )
