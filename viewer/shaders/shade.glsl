// Soft studio lighting: a slightly wrapped Lambert key light, a sky/ground hemisphere ambient, a
// little Blinn specular and a cool rim that separates the silhouette from the background.
vec3 shade(vec3 n, vec3 to_eye, vec3 color) {
    vec3 l = normalize(u_light_dir);
    float key = clamp((dot(n, l) + 0.25) / 1.25, 0.0, 1.0);
    float sky = 0.5 + 0.5 * n.y;
    vec3 ambient = mix(vec3(0.42, 0.38, 0.36), vec3(0.9, 0.95, 1.05), sky);
    float spec = pow(max(dot(n, normalize(l + to_eye)), 0.0), 48.0) * u_specular * 2.0;
    float rim = pow(1.0 - max(dot(n, to_eye), 0.0), 4.0) * 0.25 * sky;
    return color * (u_ambient * 0.9 * ambient + u_diffuse * 1.15 * key) + vec3(spec) + rim * vec3(0.7, 0.8, 1.0);
}
