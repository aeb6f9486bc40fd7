"""``flowtact run GRAPH --view``: the run's streams drawn live in a browser.

The graph side only appends to bounded buffers (:mod:`.buffers`, fed by the tee sink of
:mod:`.tee`); a server thread (:mod:`.server`, aiohttp) takes them at a bounded frame rate, turns
them into one message per frame (:mod:`.frames`) and hands it to each browser through a
drop-oldest queue, so a slow or paused browser never slows the graph. The page (``page.html``) draws
with the vendored uPlot (``vendor/``, MIT), never a CDN. Needs the ``view`` extra.
"""
