"""``arshadow preview``: place the object by hand in a browser page, rendered by the real pipeline.

- :mod:`arshadow.preview.edit`: the page's controls -> job-file keys (checked), the ground point under a
  pixel, the saved file's paths and the equivalent command line (no GL);
- :mod:`arshadow.preview.worker`: one render thread, the newest request only (latest wins);
- :mod:`arshadow.preview.engine`: the input's frames and one :class:`arshadow.frame.session.Session` rendering
  the requests, saving the scene file;
- :mod:`arshadow.preview.server`: the HTTP server (standard library, 127.0.0.1, a token) and
  ``page.html`` (package data: the page, its script and style in one file).
"""
