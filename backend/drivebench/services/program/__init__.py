"""Program download (CiA 302-3): a firmware file checked, sent to 0x1F50 as a job, started and verified."""
