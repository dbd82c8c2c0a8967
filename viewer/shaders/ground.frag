#version 330
// A checkerboard with grid lines that fades into the background.
uniform float u_tile;
uniform vec3 u_color_a;
uniform vec3 u_color_b;
uniform vec3 u_line_color;
uniform vec3 u_background;
uniform vec2 u_center;
uniform float u_size;
in vec3 v_world;
out vec4 f_color;
void main() {
    vec2 p = v_world.xz / u_tile;
    vec2 fw = max(fwidth(p), vec2(1e-6));
    // far away a tile covers few pixels: blend the checker to its mean instead of aliasing
    float blur = smoothstep(0.15, 0.5, max(fw.x, fw.y));
    vec2 cell = floor(p);
    float checker = mix(mod(cell.x + cell.y, 2.0), 0.5, blur);
    vec3 col = mix(u_color_a, u_color_b, checker);
    vec2 dist_px = abs(fract(p - 0.5) - 0.5) / fw;   // distance to the nearest grid line, pixels
    float line = (1.0 - clamp(min(dist_px.x, dist_px.y) - 0.25, 0.0, 1.0)) * (1.0 - blur);
    col = mix(col, u_line_color, line);
    float r = length(v_world.xz - u_center) / (0.5 * u_size);
    col = mix(col, u_background, smoothstep(0.55, 1.0, r));
    f_color = vec4(col, 1.0);
}
