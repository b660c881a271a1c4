"""The range classifiers on disk: the model directory's fitted forests and metadata, and
classifying measured nights with them (:mod:`.saved`); the same forests as plain arrays that
classify without scikit-learn (:mod:`.compact`)."""
