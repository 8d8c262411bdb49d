"""bboxtune environments, episode sources (simulator, OTB-100 replay) and OTB-standard metrics."""
