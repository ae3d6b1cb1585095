"""Handing work to compositing and 3D tools: layer files (:mod:`.layerfiles`, :mod:`.layervideo`) and the
camera track (:mod:`.track`: glTF 2.0, JSON, CSV). docs/export.md."""
