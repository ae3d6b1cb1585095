"""Camera views of a marker at the origin shared by the corner-refinement tests (``test_ecc_refine``,
``test_edge_refine``): ``(eye, target)`` pairs for :func:`arshadow.synth.markers.look_at_pose`, tilted and
rolled, one nearly frontal (52-94 px markers at 1280 x 720 for a 5 cm marker; half that at 640 x 360)."""

VIEWS = [
    ([0.1, -0.2, 0.45], [0, 0, 0]),
    ([-0.25, -0.3, 0.35], [0.02, 0, 0]),
    ([0.3, 0.1, 0.5], [0, 0.01, 0]),
    ([0.0, -0.1, 0.7], [0, 0, 0]),
    ([-0.1, 0.35, 0.4], [0, 0, 0]),
    ([0.2, 0.2, 0.9], [0, 0, 0]),
]
