"""What the house recorded read-only: the owner records, one per local day
(:mod:`.owner_records`), and what the house's own sensors said at each sample
(:mod:`.house_inputs`)."""
