"""The learned representations of PL-LS: V_s (state VAE) and V_a (action VAE).

Modules, bottom-up (each imports only those above it):

- :mod:`.pixel_trunk` the conv trunk every pixel network runs through (channels_last, fp32 | bf16)
- :mod:`.models`      the two VAEs (architecture only)
- :mod:`.keys`        what identifies a trained model: key, hash, artifact files, the preset that builds it
- :mod:`.fit`, :mod:`.samples`   the minibatch training loop; reconstruction samples for the figures
- :mod:`.train`       ``build``: train one model into an artifact directory; ``new_model``
- :mod:`.store`       the artifacts: verify, get-or-build, load; ``ensure_representations(cfg)``
  (a runner's setup: builds what is missing) and ``load_representations(cfg)`` (never trains)
- :mod:`.latent_wrappers` PL-LS's vector-env wrappers around the trained V_s and V_a
- :mod:`.build_run`   the ``repr`` runner: build/reuse, then record metrics into the run
- :mod:`.accounting`  parameter counts and architecture summaries (any module, not only VAEs)

Nothing is imported here, so ``import plls_bench.repr.keys`` stays free of torch.

Layer ``representations`` of tests/test_imports.py: imports only from itself and the layers below
it (``core`` up to ``tasks``); no layer below imports it.
"""
