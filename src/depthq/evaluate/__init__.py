"""Online evaluation of policies in the 20 unseen evaluation canyons (Table I's online columns)."""
