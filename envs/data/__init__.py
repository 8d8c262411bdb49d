"""The data layer of :mod:`envs`: box conventions, OTB metrics, the OTB-100 reader and split, and the track
simulator. numpy (and :mod:`filters`) only: nothing here imports Gymnasium or the layers above."""
