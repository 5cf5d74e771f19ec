"""The product's top: one run of a recording (:func:`amrvio.app.run.run`), many recordings on a
process pool or a Ray cluster (:mod:`amrvio.app.batch`), and the progress line."""
