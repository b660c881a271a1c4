"""What the owner had, kept so that it can be put back: the store's restore journal
(:mod:`.journal`) and its copy outside the database (:mod:`.owner_file`)."""
