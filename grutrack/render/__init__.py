"""Bird's-eye renders of a tracking run with the evaluator's own decisions (true positive, false positive, miss,
id switch) drawn on the scene. :mod:`grutrack.render.views` joins the boxes with the decisions (numpy only);
:mod:`grutrack.render.draw` draws them (matplotlib, imported lazily). Sits at the report layer: it reads data
and evaluation, nothing below imports it."""
