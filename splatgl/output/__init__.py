"""Everything a render becomes: the layers a renderer returns and the files a command writes (images, video, frame sequences, several files all or nothing)."""
