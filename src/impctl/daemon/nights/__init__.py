"""Which nights run and when: the local window and campaign plan (:mod:`.schedule`), the next
night (:mod:`.next_night`), manual nights waiting (:mod:`.waiting`), the adaptive campaign
(:mod:`.adaptive`) and the owner's recordings (:mod:`.recording`)."""
