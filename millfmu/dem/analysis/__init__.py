"""What DEM runs are read for: zone statistics (:mod:`.stats`), flow structure
(:mod:`.flow_structure`), run folders side by side (:mod:`.compare`) and plots
(:mod:`.plots`)."""
