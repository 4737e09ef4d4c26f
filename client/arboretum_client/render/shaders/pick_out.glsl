// Fragment outputs: the colour, or (compiled with PICK) the integer id written to the picking buffer.
#ifdef PICK
out int f_id;
#else
out vec4 f_color;
#endif
